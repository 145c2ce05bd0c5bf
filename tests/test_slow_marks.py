"""The slow lists in tests/conftest.py name real modules and tests, so ``make test-fast`` leaves out what they say."""

from __future__ import annotations

import re

from tests.conftest import REPO, SLOW_MODULES, SLOW_TESTS


def test_every_slow_module_exists():
    missing = sorted(m for m in SLOW_MODULES if not (REPO / m).is_file())
    assert not missing, f"SLOW_MODULES names files that do not exist: {missing}"


def test_every_slow_test_is_defined_in_its_module():
    missing = []
    for node in sorted(SLOW_TESTS):
        path, _, name = node.partition("::")
        file = REPO / path
        if not file.is_file() or not re.search(rf"^\s*def {re.escape(name)}\(", file.read_text(encoding="utf-8"), re.M):
            missing.append(node)
    assert not missing, f"SLOW_TESTS names tests that do not exist: {missing}"
    assert not {n.partition("::")[0] for n in SLOW_TESTS} & SLOW_MODULES, "a test listed in a slow module"
