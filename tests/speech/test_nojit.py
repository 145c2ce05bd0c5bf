"""The default path (``speak TEXT --save``, simulated) compiles no numba function, even with an empty cache.

A first ``robogest speak`` once spent ~20 s of its 25 s compiling librosa's numba kernels; the front-end now
does that analysis in numpy/scipy (:mod:`robogest.speech.dsp`). These tests run the CLI in a fresh
interpreter, as a new user would, with ``NUMBA_CACHE_DIR`` pointed at an empty folder.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("espeakng_loader")
pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
SENTENCE = "Hello there, nice to meet you."

#: Runs the CLI in-process and prints, as JSON: the numba functions compiled (numba imported first, its compile
#: event and the dispatcher's compile entry point both recorded), and whether librosa/numba got imported.
_PROBE = """
import json, sys
watch = sys.argv[1] == "watch"
compiled = []
if watch:
    from numba.core import dispatcher, event

    class Listener(event.Listener):
        def on_start(self, ev):
            compiled.append(repr(ev.data.get("dispatcher")))

        def on_end(self, ev):
            pass

    event.register("numba:compile", Listener())
    original = dispatcher.Dispatcher._compile_for_args

    def recording(self, *args, **kws):
        compiled.append(getattr(self.py_func, "__qualname__", repr(self)))
        return original(self, *args, **kws)

    dispatcher.Dispatcher._compile_for_args = recording
from robogest.cli.main import main

rc = main(["speak", sys.argv[2], "--save", sys.argv[3]])
print(json.dumps({"rc": rc, "compiled": compiled, "librosa": "librosa" in sys.modules,
                  "numba": "numba" in sys.modules}))
"""


def _probe(tmp_path: Path, watch: bool) -> dict:
    cache = tmp_path / "numba_cache"
    cache.mkdir(exist_ok=True)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl"}
    out = tmp_path / "x.npz"
    res = subprocess.run(
        [sys.executable, "-c", _PROBE, "watch" if watch else "plain", SENTENCE, str(out)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert report["rc"] in (0, None) and out.is_file()
    report["cache_files"] = sorted(p.name for p in cache.rglob("*") if p.is_file())
    return report


def test_default_path_compiles_nothing_with_empty_cache(tmp_path):
    pytest.importorskip("numba")
    report = _probe(tmp_path, watch=True)
    assert report["compiled"] == [], f"numba compiled on the default path: {report['compiled'][:10]}"
    assert report["cache_files"] == []  # nothing compiled with cache=True either
    assert not report["librosa"]


def test_default_path_imports_neither_numba_nor_librosa(tmp_path):
    report = _probe(tmp_path, watch=False)
    assert not report["numba"] and not report["librosa"]
