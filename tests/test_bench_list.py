"""benchmarks/run.py (``make bench``) runs every benchmark script, and docs/evaluation.md lists each one."""

from __future__ import annotations

import importlib.util
import re
import sys

from tests.conftest import REPO


def _run_module():
    spec = importlib.util.spec_from_file_location("bench_run", REPO / "benchmarks" / "run.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_run"] = module  # its dataclass looks its module up
    spec.loader.exec_module(module)
    return module


def test_run_py_runs_every_benchmark_script():
    scripts = {p.name for p in (REPO / "benchmarks").glob("bench_*.py")}
    listed = [b.script for b in _run_module().BENCHES]
    assert len(listed) == len(set(listed))
    assert set(listed) == scripts


def test_the_benchmarks_section_names_every_script_make_bench_runs():
    text = (REPO / "docs" / "evaluation.md").read_text(encoding="utf-8")
    section = text[text.index("\n## Benchmarks") :]
    section = section[: section.find("\n## ", 1)] if "\n## " in section[1:] else section
    named = set(re.findall(r"bench_\w+\.py", section))
    assert {b.script for b in _run_module().BENCHES} <= named
