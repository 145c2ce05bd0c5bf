"""The wheel carries the robots: build it, install it outside the checkout, speak on the sim from a temp folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
#: What a source distribution holds (the build needs nothing else).
SOURCES = ("robogest", "robots", "sim", "setup.py", "pyproject.toml", "README.md")


def _run(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"{cmd} failed ({res.returncode}):\n{res.stdout}\n{res.stderr}"
    return res


@pytest.mark.slow
def test_installed_wheel_ships_robots_and_speaks(tmp_path):
    pytest.importorskip("setuptools", minversion="70.1", reason="the dev extras install it: pip install -e '.[dev]'")
    # Build from a copy so the checkout gets no build/ or egg-info (and nothing outside the sources leaks in).
    src = tmp_path / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in SOURCES:
        p = REPO / name
        (shutil.copytree(p, src / name, ignore=ignore) if p.is_dir() else shutil.copy2(p, src / name))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    _run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(tmp_path / "dist"), "./src"], cwd=tmp_path)
    (wheel,) = (tmp_path / "dist").glob("robogest-*.whl")
    site = tmp_path / "site"
    _run([*pip, "install", "--no-deps", "--no-compile", "--target", str(site), str(wheel)], cwd=tmp_path)

    # A user's folder: no robots/ here, no ROBOGEST_ROBOTS; only the installed copy can supply robots.
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("ROBOGEST_ROBOTS", "PYTHONPATH")}
    env["PYTHONPATH"] = str(site)
    where = _run([sys.executable, "-c", "import robogest; print(robogest.__file__)"], cwd=work, env=env).stdout
    assert Path(where.strip()).is_relative_to(site)

    script = site / "bin" / "robogest"
    shown = _run([str(script), "robots", "show", "desk_arm_sts3215"], cwd=work, env=env).stdout
    model = next(line for line in shown.splitlines() if line.startswith("model:")).split(":", 1)[1].strip()
    assert Path(model).is_relative_to(site / "robogest" / "_assets" / "sim") and Path(model).is_file()

    spoken = _run([str(script), "speak", "Hi there.", "--save", "hi.npz"], cwd=work, env=env).stdout
    assert "sim tracking error" in spoken
    with np.load(work / "hi.npz") as z:
        assert str(z["robot"]) == "humanoid_xl430" and z["q_rad"].shape[1] == 11
