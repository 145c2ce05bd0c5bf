"""Find robot YAMLs by name along a documented search path.

Search order (the first folder holding ``NAME.yaml`` or ``NAME.yml`` wins on a name clash):

1. ``--robot PATH.yaml``: a path is loaded as is, no search;
2. ``$ROBOGEST_ROBOTS``: one or more folders (``os.pathsep``-separated), in the order given;
3. ``./robots/`` in the current directory;
4. the robots packaged with robogest (:func:`robots_dir`).

A robot file's ``base: NAME`` (:mod:`robogest.robot.inherit`) is looked up beside that file first, then along the
same path (:func:`find_base`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.errors import ConfigError

if TYPE_CHECKING:  # the config (numpy, pydantic) loads when a robot is first looked up
    from robogest.robot.config import RobotConfig

#: The robot `speak` uses when none is named.
DEFAULT_ROBOT = "humanoid_xl430"


def robots_dir() -> Path:
    """The shipped robot YAMLs: inside the installed package, or the checkout's ``robots/`` when run from source.

    The wheel carries the repository's ``robots/`` and ``sim/`` as ``robogest/_assets/`` (see ``setup.py``);
    a source checkout (editable install, PYTHONPATH) has no ``_assets`` and keeps them beside the package.
    """
    from importlib.resources import files

    package = Path(str(files("robogest")))
    installed = package / "_assets" / "robots"
    return installed if installed.is_dir() else package.parent / "robots"


def search_path() -> list[Path]:
    """Folders searched for ``NAME.yaml``, first match winning (the module docstring gives the order)."""
    extra = [Path(p) for p in os.environ.get("ROBOGEST_ROBOTS", "").split(os.pathsep) if p]
    return [*extra, Path.cwd() / "robots", robots_dir()]


def list_robots() -> dict[str, Path]:
    """Robot name -> YAML path, earlier folders winning."""
    found: dict[str, Path] = {}
    for d in search_path():
        if not d.is_dir():
            continue
        # .yaml before .yml of the same name in one folder; --robot PATH takes either
        for f in sorted([*d.glob("*.yaml"), *d.glob("*.yml")], key=lambda f: (f.stem, f.suffix != ".yaml")):
            found.setdefault(f.stem, f)
    return found


def find_base(name: str, beside: Path) -> Path | None:
    """The YAML of robot ``name`` that the robot file ``beside`` names as its ``base:``: ``NAME.yaml`` (or
    ``.yml``) in that file's own folder, else the first along :func:`search_path`; None when there is none."""
    for suffix in (".yaml", ".yml"):
        own = beside.parent / f"{name}{suffix}"
        if own.is_file() and own.resolve() != beside.resolve():
            return own
    return list_robots().get(name)


def find_robot(name_or_path: str) -> RobotConfig:
    """Load a robot by name (``humanoid_xl430``) or by path to its YAML."""
    from robogest.robot.config import load_robot_config

    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.is_file():
        return load_robot_config(p)
    robots = list_robots()
    if name_or_path not in robots:
        known = ", ".join(sorted(robots)) or "(none found)"
        searched = ", ".join(str(d) for d in search_path())
        raise ConfigError(
            f"unknown robot {name_or_path!r}; known robots: {known} (searched {searched}; "
            "or pass a path to a YAML file)"
        )
    return load_robot_config(robots[name_or_path])
