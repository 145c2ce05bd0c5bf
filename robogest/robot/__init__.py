"""Robot definitions (YAML) and where to find them.

The schema (:mod:`.config`, :mod:`.inherit`), the registry (:mod:`.registry`), the one MJCF loader (:mod:`.mjcf`),
the one robot-YAML writer (:mod:`.yaml_edit`) and the model/YAML mapping problems (:mod:`.problems`). Nothing here
imports a later stage; the robot tools (validate, import, calibration import) are :mod:`robogest.tools`.

Names load on first use (module ``__getattr__``) so that finding a robot's name costs no numpy/pydantic import.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig, load_robot_config
    from robogest.robot.registry import find_robot, list_robots, robots_dir

from robogest._lazy import lazy_getattr

_LAZY = {
    "RobotConfig": "robogest.robot.config",
    "load_robot_config": "robogest.robot.config",
    "find_robot": "robogest.robot.registry",
    "list_robots": "robogest.robot.registry",
    "robots_dir": "robogest.robot.registry",
}

__getattr__ = lazy_getattr(__name__, _LAZY)


__all__ = ["RobotConfig", "find_robot", "list_robots", "load_robot_config", "robots_dir"]
