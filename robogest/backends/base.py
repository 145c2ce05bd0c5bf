"""The seam between trajectories and whatever moves: MuJoCo, Dynamixel or Feetech servos.

Backends speak radians at the joint; ticks, offsets and gearing stay inside each implementation.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from types import TracebackType

import numpy as np

from robogest.registry import Registry
from robogest.robot.config import RobotConfig


class Backend(ABC):
    """Connect, read, torque, stream goals, disconnect.

    Used as a context manager, leaving the block (normally, by exception or Ctrl-C) always calls
    :meth:`shutdown`, which moves to rest if the robot still answers and then turns torque off.
    """

    #: True when time passes by itself (hardware); False when :meth:`advance` drives a simulator.
    realtime: bool = True

    def __init__(self, robot: RobotConfig) -> None:
        self.robot = robot
        #: Ticks per second of whoever streams goals (:meth:`set_control_rate`); the go-to-rest uses it too.
        self.control_rate_hz = 100.0

    def set_control_rate(self, rate_hz: float) -> None:
        """Tick rate of the caller, Hz (called by the control loop before it connects)."""
        self.control_rate_hz = float(rate_hz)

    @property
    def joint_names(self) -> list[str]:
        return self.robot.joint_names

    @abstractmethod
    def connect(self) -> None:
        """Open the port/simulator and check every joint answers."""

    @abstractmethod
    def read_positions(self) -> np.ndarray:
        """Present joint angles ``(J,)``, radians."""

    @abstractmethod
    def set_torque(self, on: bool) -> None:
        """Enable or disable holding torque on every joint."""

    @abstractmethod
    def write_goal(self, q_rad: np.ndarray) -> None:
        """Command joint angles ``(J,)``, radians (already inside the limits)."""

    @abstractmethod
    def disconnect(self) -> None:
        """Release the port/simulator; must be safe to call twice."""

    def advance(self, dt_s: float) -> None:  # noqa: B027 - optional hook
        """Advance simulated time; hardware ignores it (the player waits on the clock instead)."""

    def shutdown(self) -> None:
        """Torque off and disconnect. Subclasses that can move to rest first
        (:func:`~robogest.backends.control.go_to_rest`) override this."""
        try:
            self.set_torque(False)
        finally:
            self.disconnect()

    def __enter__(self) -> Backend:
        self.connect()
        return self

    def __exit__(self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.shutdown()


BackendFactory = Callable[..., Backend]
#: Backends by name; each factory takes ``(robot, port=None, baudrate=None, **options)``.
BACKENDS: Registry[BackendFactory] = Registry("backend")
register_backend = BACKENDS.register
backend_names = BACKENDS.names
get_backend_factory = BACKENDS.get
