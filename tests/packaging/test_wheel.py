"""The wheel carries the robots and ``py.typed``: build it, install it outside the checkout, speak on the sim from a
temp folder; a missing extra names the wheel to install it from."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
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
    with zipfile.ZipFile(wheel) as zf:
        assert "robogest/py.typed" in zf.namelist()
        meta = zf.read(next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA"))).decode()
    core = [line for line in meta.splitlines() if line.startswith("Requires-Dist:") and "extra ==" not in line]
    assert core and not [line for line in core if re.match(r"Requires-Dist: (av|matplotlib)\b", line)]
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
    assert _run([str(script), "--version"], cwd=work, env=env).stdout == f"robogest {wheel.name.split('-')[1]}\n"

    # Without PyAV the installed copy names the wheel it came from (robogest is on no index).
    from tests.packaging.test_extras import SHIM

    cmd = [sys.executable, "-c", SHIM, json.dumps([["speak", "Hi.", "--video", "hi.mp4"]])]
    res = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert '"rcs": [6]' in res.stdout and not (work / "hi.mp4").exists()
    assert "--video needs the video extra (av is not installed); install it: " in res.stderr
    assert res.stderr.rstrip().endswith(f"pip install '{wheel}[video]'"), res.stderr
