"""`robogest --help` and `import robogest` stay light: no numpy, scipy, librosa, mujoco or rich at start-up."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("numpy", "scipy", "librosa", "mujoco", "rich", "pydantic", "torch")


def _loaded_after(code: str) -> set[str]:
    probe = f"{code}\nimport sys\nprint(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    return set(out.split()) & set(HEAVY)


def test_help_parser_imports_nothing_heavy():
    assert _loaded_after("from robogest.cli.main import build_parser; build_parser().format_help()") == set()


def test_import_robogest_is_light_and_names_resolve_lazily():
    assert _loaded_after("import robogest; robogest.__all__") == set()
    import robogest

    assert "Robot" in robogest.__all__ and callable(robogest.list_robots)
    assert "humanoid_xl430" in robogest.list_robots()


def test_dir_lists_the_public_names_without_loading_them():
    assert _loaded_after("import robogest; dir(robogest)") == set()
    import robogest

    names = dir(robogest)
    assert {"Robot", "UtteranceHandle", "AsyncRobot", "aio", "list_robots"} <= set(names)
    assert "lazy_getattr" not in names and "TYPE_CHECKING" not in names
    assert all(hasattr(robogest, n) for n in robogest.__all__)
