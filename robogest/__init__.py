"""Co-speech gestures for servo-driven humanoid robots.

The names a user needs load on first use (module ``__getattr__``), so ``import robogest`` and
``robogest --help`` stay fast::

    from robogest import Robot
    with Robot("humanoid_xl430", backend="sim") as robot:
        robot.say("Hello! Nice to meet you.")
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from robogest._version import __version__ as __version__
    from robogest.errors import RobogestError
    from robogest.live import Robot, UtteranceHandle
    from robogest.robot.registry import find_robot, list_robots
    from robogest.speech import load_speech, synthesize

from robogest._lazy import lazy_getattr

_LAZY = {
    "__version__": "robogest._version",
    "Robot": "robogest.live",
    "UtteranceHandle": "robogest.live",
    "RobogestError": "robogest.errors",
    "find_robot": "robogest.robot.registry",
    "list_robots": "robogest.robot.registry",
    "load_speech": "robogest.speech",
    "synthesize": "robogest.speech",
}

__getattr__ = lazy_getattr(__name__, _LAZY)


__all__ = ["RobogestError", "Robot", "UtteranceHandle", "find_robot", "list_robots", "load_speech", "synthesize"]
