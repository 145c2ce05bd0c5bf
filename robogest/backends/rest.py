"""The one go-to-rest for a backend without a running control loop (every backend's ``shutdown`` uses it), and the
goal that holds a robot's present pose when a loop starts. Re-exported by :mod:`robogest.backends.control`."""

from __future__ import annotations

import time

import numpy as np

from robogest.backends.base import Backend
from robogest.errors import RobogestError
from robogest.robot.config import RobotConfig

#: Default control rate, Hz.
DEFAULT_RATE_HZ = 100.0


def start_pose(q_read_rad: np.ndarray, robot: RobotConfig, period_s: float) -> np.ndarray:
    """The goal that holds the present pose ``(J,)`` at start: the reading, clipped into the limits, with each held
    joint moved half a tick's allowed step towards its angle (onto it when that close). The goal guard reads the
    pose again for its reference, and a held joint's goal must not be farther from its angle than that reference:
    half a step covers the reading's noise (a tick or two) where the reading itself could be refused."""
    q = np.clip(np.asarray(q_read_rad, dtype=float), robot.q_min_rad, robot.q_max_rad)
    rest, step = robot.rest_q_rad, 0.5 * robot.v_max_rad_s * period_s
    held: np.ndarray = np.where(robot.held_mask, q + np.clip(rest - q, -step, step), q)
    return held


def go_to_rest(backend: Backend, rate_hz: float | None = None) -> str | None:
    """Glide ``backend`` from its last goal (or present pose) to rest within every limit; the one go-to-rest.

    For a backend without a running :class:`ControlLoop` (every backend's ``shutdown`` calls it; after a loop's
    own glide it finds the robot at rest and returns at once). It starts from the last goal, moving and
    accelerating as the goal stream did if that goal was sent within the last two control periods (a simulated
    backend: always), so the goals brake within the acceleration limit instead of stopping dead; else still.
    ``rate_hz`` defaults to the backend's control rate (so per-tick steps stay what its guard expects). Torque
    is left as it is.
    Returns None at rest, else why not.
    """
    from robogest.backends.control import ControlLoop  # (it imports this module)

    rate = float(getattr(backend, "control_rate_hz", DEFAULT_RATE_HZ)) if rate_hz is None else rate_hz
    loop = ControlLoop(backend, rate, threaded=False)
    last = getattr(backend, "last_goal_rad", None)
    v0 = getattr(backend, "last_goal_v_rad_s", None)
    a0 = getattr(backend, "last_goal_a_rad_s2", None)
    recent = time.monotonic() - getattr(backend, "last_goal_monotonic_s", -np.inf) <= 2 * backend.control_period_s
    try:
        q0 = (
            np.asarray(last, dtype=float)
            if last is not None
            else start_pose(backend.read_positions(), backend.robot, backend.control_period_s)
        )
    except RobogestError as e:
        return f"could not reach rest ({e})"
    moving = last is not None and v0 is not None and (recent or not backend.realtime)
    if moving and a0 is not None:  # a backward difference is the velocity half a period back
        v0 = v0 + 0.5 * a0 * backend.control_period_s
    q0 = np.clip(q0, backend.robot.q_min_rad, backend.robot.q_max_rad)
    return loop.glide_from(q0, v0 if moving else None, a0 if moving else None)
