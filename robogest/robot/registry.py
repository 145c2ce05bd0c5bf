"""Find robot YAMLs by name: ``$ROBOGEST_ROBOTS`` (os.pathsep-separated) first, then the repo's ``robots/``."""

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
    """The ``robots/`` folder shipped beside the package."""
    return Path(__file__).resolve().parents[2] / "robots"


def _search_path() -> list[Path]:
    extra = [Path(p) for p in os.environ.get("ROBOGEST_ROBOTS", "").split(os.pathsep) if p]
    return [*extra, robots_dir()]


def list_robots() -> dict[str, Path]:
    """Robot name -> YAML path, earlier folders winning."""
    found: dict[str, Path] = {}
    for d in _search_path():
        for f in sorted(d.glob("*.yaml")) if d.is_dir() else []:
            found.setdefault(f.stem, f)
    return found


def find_robot(name_or_path: str) -> RobotConfig:
    """Load a robot by name (``humanoid_xl430``) or by path to its YAML."""
    from robogest.robot.config import load_robot_config

    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.is_file():
        return load_robot_config(p)
    robots = list_robots()
    if name_or_path not in robots:
        known = ", ".join(sorted(robots)) or "(none found)"
        raise ConfigError(f"unknown robot {name_or_path!r}; known robots: {known} (or pass a path to a YAML file)")
    return load_robot_config(robots[name_or_path])
