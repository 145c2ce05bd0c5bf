"""Extras per part: bounded dependencies, a missing extra is exit 6 with the pip command before any work, the core
path needs neither PyAV nor matplotlib, ``robogest.__version__``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import robogest
from robogest import extras
from robogest.cli.main import main
from robogest.errors import MissingDependencyError

REPO = Path(__file__).resolve().parents[2]
#: Extra -> the module the tests make unimportable.
BLOCKED = {"video": "av", "plot": "matplotlib"}


def _pyproject() -> dict:
    tomllib = pytest.importorskip("tomllib", reason="Python >= 3.11 reads TOML")
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_every_dependency_has_an_upper_bound():
    requirements = pytest.importorskip("packaging.requirements")
    project = _pyproject()
    listed = [*project["build-system"]["requires"], *project["project"]["dependencies"]]
    listed += [r for reqs in project["project"]["optional-dependencies"].values() for r in reqs]
    unbounded = []
    for text in listed:
        req = requirements.Requirement(text)
        if req.name != "robogest" and not any(s.operator in ("<", "<=", "==", "~=") for s in req.specifier):
            unbounded.append(text)
    assert not unbounded, f"no upper bound on the major: {unbounded}"


def test_core_has_no_video_or_plot_library_and_all_has_every_extra():
    project = _pyproject()["project"]
    core = " ".join(project["dependencies"])
    assert "av" not in re.findall(r"[\w.-]+", core) and "matplotlib" not in core
    optional = project["optional-dependencies"]
    assert optional["video"][0].startswith("av") and optional["plot"][0].startswith("matplotlib")
    wanted = sorted(set(optional) - {"all", "dev"})
    (everything,) = optional["all"]
    assert sorted(re.fullmatch(r"robogest\[(.*)\]", everything).group(1).split(",")) == wanted
    assert "robogest[all]" in optional["dev"]
    assert sorted(extras.EXTRAS) == wanted  # every extra has its modules listed for the exit-6 check


def test_version_is_the_project_version(monkeypatch, capsys):
    declared = re.search(r'^version = "(.+)"', (REPO / "pyproject.toml").read_text(), re.M).group(1)
    assert robogest.__version__ == declared
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out == f"robogest {declared}\n"

    import importlib.metadata

    from robogest import _version

    def not_installed(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    assert _version._version() == declared  # from the checkout's pyproject.toml
    monkeypatch.setattr(extras, "source_checkout", lambda: None)
    assert _version._version() == "0+unknown"


def test_install_command_names_where_robogest_came_from(monkeypatch, tmp_path):
    monkeypatch.setattr(extras, "_pip", lambda: "pip")
    monkeypatch.chdir(REPO)
    assert extras.source_checkout() == REPO
    assert extras.install_command("video") == "pip install -e '.[video]'"
    monkeypatch.chdir(tmp_path)
    assert extras.install_command("plot") == f"pip install -e '{REPO}[plot]'"

    monkeypatch.setattr(extras, "source_checkout", lambda: None)
    wheel = tmp_path / "dist" / "robogest-0.1.0-py3-none-any.whl"
    monkeypatch.setattr(extras, "installed_wheel", lambda: wheel)
    assert extras.install_command("video") == f"pip install '{wheel}[video]'"
    monkeypatch.setattr(extras, "installed_wheel", lambda: None)
    assert extras.install_command("video") == "pip install 'robogest[video]'"


def test_installed_wheel_is_read_from_pips_direct_url(monkeypatch, tmp_path):
    import importlib.metadata

    wheel = tmp_path / "robogest-0.1.0-py3-none-any.whl"

    class Dist:
        def read_text(self, name: str) -> str | None:
            return json.dumps({"url": wheel.as_uri(), "archive_info": {}}) if name == "direct_url.json" else None

    monkeypatch.setattr(importlib.metadata, "distribution", lambda name: Dist())
    assert extras.installed_wheel() is None  # the wheel is gone: no path that would fail
    wheel.write_bytes(b"")
    assert extras.installed_wheel() == wheel


def test_pip_of_this_python(monkeypatch, tmp_path):
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name: str(Path(sys.executable).parent / name))
    assert extras._pip() == "pip"
    monkeypatch.setattr(shutil, "which", lambda name: str(tmp_path / name))  # another Python's pip on PATH
    assert extras._pip() == f"{sys.executable} -m pip"


def _block(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in BLOCKED.values():
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError, find_spec finds nothing


@pytest.mark.parametrize(
    ("argv", "extra", "outputs"),
    [
        (["speak", "Hi there.", "--save", "a.npz", "--video", "a.mp4"], "video", ["a.npz", "a.wav", "a.mp4"]),
        (["speak", "Hi there.", "--save", "a.npz", "--plot", "a.png"], "plot", ["a.npz", "a.wav", "a.png"]),
        (["play", "t.npz", "--video", "a.mp4"], "video", ["a.mp4"]),
        (["generate", "--text", "Hi there.", "--out", "m.bvh", "--plot", "a.png"], "plot", ["m.bvh", "a.png"]),
        (["eval", "--pred", "t.npz", "--plots", "plots"], "plot", ["plots"]),
    ],
    ids=["speak-video", "speak-plot", "play-video", "generate-plot", "eval-plots"],
)
def test_missing_extra_is_exit_6_with_the_command_before_any_work(argv, extra, outputs, monkeypatch, tmp_path, capsys):
    monkeypatch.chdir(tmp_path)
    _block(monkeypatch)
    monkeypatch.setattr(extras, "_pip", lambda: "pip")
    assert main(argv) == 6
    err = capsys.readouterr().err
    flag = next(a for a in argv if a in ("--video", "--plot", "--plots"))
    assert err == f"robogest: error: {flag} needs the {extra} extra ({BLOCKED[extra]} is not installed); " \
                  f"install it: pip install -e '{REPO}[{extra}]'\n"  # fmt: skip
    assert not [o for o in outputs if os.path.lexists(tmp_path / o)]


def test_missing_extra_message_lists_every_missing_module(monkeypatch):
    monkeypatch.setitem(extras.EXTRAS, "video", ("av", "no_such_module_xyz"))
    monkeypatch.setitem(sys.modules, "av", None)
    with pytest.raises(MissingDependencyError, match=r"--video needs the video extra \(av, "
                       r"no_such_module_xyz are not installed\); install it: .*pip install"):  # fmt: skip
        extras.require_extra("video", "--video")


#: Runs robogest's CLI with PyAV and matplotlib unimportable, and reports every attempt to import them.
SHIM = r"""
import json, sys
tried = []
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("av", "matplotlib"):
            tried.append(name)
            raise ImportError(f"{name} blocked by the test")
        return None
sys.meta_path.insert(0, Block())
from robogest.cli.main import main
rcs = [main(argv) for argv in json.loads(sys.argv[1])]
print("RESULT", json.dumps({"rcs": rcs, "tried": sorted(set(tried))}))
"""


@pytest.mark.slow
def test_core_path_needs_neither_pyav_nor_matplotlib(tmp_path):
    """``speak --save`` on the sim and ``robots show --render`` with PyAV and matplotlib unimportable: both work,
    and nothing even tries to import either."""
    commands = [
        ["speak", "Hi there.", "--save", "hi.npz"],
        ["play", "hi.npz"],
        ["robots", "show", "humanoid_xl430", "--render", "rest.png", "--size", "64x48"],
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run([sys.executable, "-c", SHIM, json.dumps(commands)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    line = next((s for s in proc.stdout.splitlines() if s.startswith("RESULT ")), None)
    assert line is not None, proc.stdout + proc.stderr
    result = json.loads(line.removeprefix("RESULT "))
    assert result == {"rcs": [0, 0, 0], "tried": []}, proc.stderr
    assert (tmp_path / "hi.npz").is_file() and (tmp_path / "hi.wav").is_file()
    assert (tmp_path / "rest.png").read_bytes().startswith(b"\x89PNG\r\n\x1a\n")


def test_png_writer_round_trips_without_an_image_library(tmp_path):
    """``robots show --render`` writes its PNG with the standard library (the plot extra is not needed)."""
    import struct
    import zlib

    import numpy as np

    from robogest.media.png import write_png

    rgb = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    write_png(tmp_path / "x.png", rgb)
    data = (tmp_path / "x.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, i = {}, 8
    while i < len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        kind, body, crc = data[i + 4 : i + 8], data[i + 8 : i + 8 + n], data[i + 8 + n : i + 12 + n]
        assert struct.unpack(">I", crc)[0] == zlib.crc32(kind + body)
        chunks[kind], i = body, i + 12 + n
    assert struct.unpack(">IIBBBBB", chunks[b"IHDR"]) == (7, 5, 8, 2, 0, 0, 0)
    rows = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), np.uint8).reshape(5, 1 + 7 * 3)
    assert not rows[:, 0].any() and np.array_equal(rows[:, 1:].reshape(5, 7, 3), rgb)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) RGB image, got shape \(5, 7\)"):
        write_png(tmp_path / "y.png", rgb[..., 0])
