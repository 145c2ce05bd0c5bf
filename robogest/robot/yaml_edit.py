"""The one writer of robot YAML files that robogest edits (calibrated copies): one dump style, and a file is only
published once the validated loader accepts it, so a copy that would not load never replaces anything."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from robogest.errors import ConfigError
from robogest.fileio import atomic_path
from robogest.robot.config import RobotConfig, load_robot_config


def dump_robot_yaml(doc: dict[str, Any], header: str = "") -> str:
    """``doc`` as robot YAML text: keys in the order given, short lists on one line (``[x, y, z]``), ``header``
    (comment lines, each ending in a newline) first."""
    import yaml

    return header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120)


def write_robot_yaml(path: str | Path, doc: dict[str, Any], header: str = "") -> RobotConfig:
    """Write ``doc`` (a robot definition as plain data) to ``path`` atomically and return it loaded.

    The text goes to a temporary file beside ``path`` (so relative ``model:`` paths and ``base:`` names resolve as
    they will), which :func:`load_robot_config` must accept before it replaces ``path``; otherwise ConfigError
    naming ``path`` and nothing is written. Comments of a file being replaced are not kept: pass them in ``header``.
    """
    path = Path(path)
    with atomic_path(path, suffix=".yaml") as tmp:
        tmp.write_text(dump_robot_yaml(doc, header))
        try:
            load_robot_config(tmp)
        except ConfigError as e:  # name the file it would have been, not the temporary one
            raise ConfigError(f"{str(e).replace(str(tmp), str(path))}; nothing written") from None
    return load_robot_config(path)
