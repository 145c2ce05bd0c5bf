"""Plugins: a package installed next to robogest adds a generator and a backend through entry points."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from robogest.backends.base import BACKENDS
from robogest.cli.main import main
from robogest.generators.base import GENERATORS

PLUGIN_PYPROJECT = """
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "robogest-demo-plugin"
version = "0.0.1"

[project.entry-points."robogest.generators"]
still = "robogest_demo_plugin:make_still"
broken = "robogest_demo_plugin.no_such_module:make"

[project.entry-points."robogest.backends"]
memory = "robogest_demo_plugin:MemoryBackend"
sim = "robogest_demo_plugin:MemoryBackend"
"""

PLUGIN_MODULE = '''
"""A generator that stands still and a backend that keeps every goal in memory."""
import numpy as np

from robogest.backends.base import Backend
from robogest.generators.base import Generator
from robogest.motion.human_motion import HumanMotion

GENERATED = []
GOALS = []


class Still(Generator):
    name = "still"

    def generate(self, speech, seed=0):
        GENERATED.append(seed)
        return HumanMotion.rest(speech.features.n_frames, speech.fps)


def make_still(**options):
    return Still()


class MemoryBackend(Backend):
    realtime = False

    def __init__(self, robot, port=None, baudrate=None, **options):
        super().__init__(robot)
        self.q = np.array([j.rest_rad for j in robot.joints])

    def connect(self):
        pass

    def read_positions(self):
        return self.q.copy()

    def set_torque(self, on):
        pass

    def _send_goal(self, q_rad):
        self.q = np.array(q_rad, dtype=float)
        GOALS.append(self.q.copy())

    def disconnect(self):
        pass
'''


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory) -> Path:
    """The plugin package, built and installed with pip into its own folder (put on sys.path by the test)."""
    pytest.importorskip("setuptools", minversion="70.1", reason="the dev extras install it: pip install -e '.[dev]'")
    root = tmp_path_factory.mktemp("plugin")
    src = root / "src"
    (src / "robogest_demo_plugin").mkdir(parents=True)
    (src / "pyproject.toml").write_text(textwrap.dedent(PLUGIN_PYPROJECT))
    (src / "robogest_demo_plugin" / "__init__.py").write_text(PLUGIN_MODULE)
    site = root / "site"
    cmd = [sys.executable, "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-deps",
           "--no-build-isolation", "--no-compile", "--target", str(site), str(src)]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=root)
    assert res.returncode == 0, res.stderr
    return site


@pytest.fixture
def plugin(plugin_site, monkeypatch):
    monkeypatch.syspath_prepend(str(plugin_site))
    for reg in (GENERATORS, BACKENDS):
        reg.refresh()
    import robogest_demo_plugin

    robogest_demo_plugin.GENERATED.clear()
    robogest_demo_plugin.GOALS.clear()
    yield robogest_demo_plugin
    for reg in (GENERATORS, BACKENDS):
        reg.refresh()


def test_plugin_generator_and_backend_are_found(plugin, capsys):
    assert {"still", "broken", "rhythm"} <= set(GENERATORS.names())
    assert main(["speak", "Hi there.", "--generator", "still", "--backend", "memory"]) == 0
    out = capsys.readouterr()
    assert plugin.GENERATED == [0] and len(plugin.GOALS) > 10  # its generator made the motion, its backend moved
    assert "generator: still" in out.out and "played" in out.out
    # The plugin that claims the built-in name "sim" is ignored, said in one line; the broken one is never imported.
    assert out.err.strip().splitlines() == [
        "robogest: warning: backend plugin 'sim' (robogest_demo_plugin:MemoryBackend) ignored: a built-in has that name"
    ]


def test_broken_plugin_is_one_error_line(plugin, capsys):
    assert main(["speak", "Hi there.", "--generator", "broken"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert (
        "generator 'broken' (plugin robogest_demo_plugin.no_such_module:make from package 'robogest-demo-plugin')"
        in err[0]
    )
    assert "failed to load: ModuleNotFoundError" in err[0] and "fix or uninstall that package" in err[0]


def test_without_the_plugin_the_names_are_unknown(capsys):
    for reg in (GENERATORS, BACKENDS):
        reg.refresh()
    assert main(["speak", "Hi there.", "--generator", "still"]) == 2
    assert "unknown generator 'still'; choose one of" in capsys.readouterr().err
