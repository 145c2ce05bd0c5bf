"""Co-speech gestures for servo-driven humanoid robots.

The names a user needs load on first use (module ``__getattr__``), so ``import robogest`` and
``robogest --help`` stay fast::

    from robogest import Robot
    with Robot("humanoid_xl430", backend="sim") as robot:
        robot.say("Hello! Nice to meet you.")

For asyncio programs, :class:`robogest.aio.AsyncRobot` (also ``robogest.AsyncRobot``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from robogest._version import __version__ as __version__
    from robogest.aio import AsyncRobot, AsyncStream, AsyncUtterance
    from robogest.errors import RobogestError
    from robogest.live import Robot, StreamUtterance, UtteranceHandle
    from robogest.robot.registry import find_robot, list_robots
    from robogest.speech import load_speech, synthesize

from robogest._lazy import lazy_getattr

_LAZY = {
    "__version__": "robogest._version",
    "Robot": "robogest.live",
    "UtteranceHandle": "robogest.live",
    "StreamUtterance": "robogest.live",
    "AsyncRobot": "robogest.aio",
    "AsyncStream": "robogest.aio",
    "AsyncUtterance": "robogest.aio",
    "RobogestError": "robogest.errors",
    "find_robot": "robogest.robot.registry",
    "list_robots": "robogest.robot.registry",
    "load_speech": "robogest.speech",
    "synthesize": "robogest.speech",
}

__getattr__ = lazy_getattr(__name__, _LAZY)

__all__ = [
    "AsyncRobot",
    "AsyncStream",
    "AsyncUtterance",
    "RobogestError",
    "Robot",
    "StreamUtterance",
    "UtteranceHandle",
    "find_robot",
    "list_robots",
    "load_speech",
    "synthesize",
]


def __dir__() -> list[str]:
    """The public names (loaded lazily, so not yet in the module's namespace) and the ``aio`` module; not the
    helpers this file imports."""
    return sorted({*(n for n in globals() if n.startswith("__")), *__all__, "aio"})
