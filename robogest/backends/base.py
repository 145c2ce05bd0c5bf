"""The seam between trajectories and whatever moves: MuJoCo, Dynamixel or Feetech servos.

Backends speak radians at the joint; ticks, offsets and gearing stay inside each implementation.

The last step before the hardware is :meth:`Backend.write_goal`, and it is concrete: every goal, whatever made
it (a trajectory file, the Python API, a live stream, the shutdown ramp), is checked against the robot
definition alone (finite, inside the joint limits, no faster than the velocity limit from the last goal sent)
before a subclass's :meth:`Backend._send_goal` may write anything. A held joint
(:attr:`~robogest.robot.config.JointConfig.held`) is only ever commanded to its rest angle: a goal may bring it
closer (a joint found elsewhere at connect glides onto it), never farther.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from types import TracebackType

import numpy as np

from robogest.errors import InputError, SafetyError
from robogest.registry import Registry
from robogest.robot.config import RobotConfig

#: Position slack of the goal guard (float rounding only), radians.
GOAL_POS_TOL_RAD = 1e-9
#: Relative and absolute slack of the guard's per-tick velocity bound (float rounding only).
GOAL_STEP_RTOL, GOAL_STEP_ATOL_RAD = 1e-6, 1e-9


GuardLimits = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def guard_limits(robot: RobotConfig) -> GuardLimits:
    """``(q_min_rad, q_max_rad, v_max_rad_s, rest_q_rad, held_mask)``, each ``(J,)``, read-only: what
    :func:`check_goal` compares with."""
    arrays = (robot.q_min_rad, robot.q_max_rad, robot.v_max_rad_s, robot.rest_q_rad, robot.held_mask)
    for a in arrays:
        a.setflags(write=False)
    return arrays


def check_goal(
    q_rad: np.ndarray,
    robot: RobotConfig,
    reference_rad: np.ndarray,
    period_s: float,
    source: str = "",
    limits: GuardLimits | None = None,
) -> np.ndarray:
    """The goal guard: return ``q_rad`` as a float array, or raise if any joint's goal is unsafe.

    Only the robot definition counts: a goal must be finite, inside ``[lower_rad, upper_rad]`` and within
    ``max_velocity_rad_s * period_s`` of ``reference_rad`` (the last goal sent) on every joint; a held joint's goal
    must lie between ``reference_rad`` and its rest angle (at rest: exactly there).

    Parameters
    ----------
    q_rad : ndarray [shape=(J,)], radians
    robot : RobotConfig
    reference_rad : ndarray [shape=(J,)], radians
        The last goal sent (before the first one: the present pose).
    period_s : float, seconds
        Control period: the time the joint has to make the step.
    source : str
        Where the goal came from, for the message.
    limits : tuple, optional
        ``guard_limits(robot)``, when the caller keeps it (building the arrays costs more than the check).

    Raises
    ------
    InputError
        ``q_rad`` is not a numeric ``(J,)`` array.
    SafetyError
        One line naming every offending joint, its value and the limit it breaks.
    """
    lo, hi, v_max, rest, held = limits if limits is not None else guard_limits(robot)
    try:
        q = np.array(q_rad, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"goal for {robot.name} is not a numeric array of {lo.size} joint angles") from None
    if q.shape != lo.shape:
        raise InputError(f"goal has shape {q.shape}; expected ({lo.size},) joint angles for {robot.name}")
    step_max = v_max * period_s
    step = np.abs(q - reference_rad)  # NaN/inf in q give NaN/inf here, no warning
    ok = (q >= lo - GOAL_POS_TOL_RAD) & (q <= hi + GOAL_POS_TOL_RAD)
    ok &= step <= step_max * (1 + GOAL_STEP_RTOL) + GOAL_STEP_ATOL_RAD
    off_held = np.zeros_like(held)
    if held.any():  # a held joint: between the last goal and its angle (NaN compares False here too)
        off_held = held & ~(
            (q >= np.minimum(reference_rad, rest) - GOAL_POS_TOL_RAD)
            & (q <= np.maximum(reference_rad, rest) + GOAL_POS_TOL_RAD)
        )
        ok &= ~off_held
    if ok.all():  # every comparison with NaN is False, so a finite, in-range, slow goal is the only way here
        return q
    names = robot.joint_names
    bad_value = ~np.isfinite(q)
    bad_pos = ~bad_value & ((q < lo - GOAL_POS_TOL_RAD) | (q > hi + GOAL_POS_TOL_RAD))
    bad_step = ~bad_value & ~bad_pos & ~ok
    problems = []
    for j in np.flatnonzero(bad_value | bad_pos | bad_step):
        if bad_value[j]:
            problems.append(f"{names[j]} = {q[j]} is not finite")
        elif bad_pos[j]:
            problems.append(f"{names[j]} = {q[j]:.4f} rad outside [{lo[j]:.4f}, {hi[j]:.4f}] rad")
        elif off_held[j]:
            problems.append(f"{names[j]} = {q[j]:.4f} rad moves a held joint off its angle {rest[j]:.4f} rad")
        else:
            problems.append(
                f"{names[j]} steps {step[j]:.4f} rad in one {1000 * period_s:.1f} ms tick, limit {step_max[j]:.4f} rad "
                f"({v_max[j]:g} rad/s)"
            )
    shown = "; ".join(problems[:3]) + (f"; and {len(problems) - 3} more joints" if len(problems) > 3 else "")
    raise SafetyError(
        f"unsafe goal for {robot.name} refused before the bus ({shown}); source: {source or 'write_goal caller'}; "
        "nothing was sent, the robot goes to rest with torque off; check the trajectory, stream or code that "
        "made it (limits come from the robot YAML)"
    )


class Backend(ABC):
    """Connect, read, torque, stream goals, disconnect.

    Used as a context manager, leaving the block (normally, by exception or Ctrl-C) always calls
    :meth:`shutdown`, which moves to rest if the robot still answers and then turns torque off.
    """

    #: True when time passes by itself (hardware); False when :meth:`advance` drives a simulator.
    realtime: bool = True

    def __init__(self, robot: RobotConfig) -> None:
        self.robot = robot
        #: Control rate, Hz: the goal guard allows ``max_velocity_rad_s / control_rate_hz`` per goal.
        self.control_rate_hz = 50.0
        #: The last goal that passed the guard and was sent, ``(J,)`` radians; None before the first one.
        self.last_goal_rad: np.ndarray | None = None
        #: Velocity ``(J,)`` rad/s and acceleration ``(J,)`` rad/s² of the goal stream at the last goal (finite
        #: differences over the control period; None until there are enough goals), and when it was sent
        #: (``time.monotonic()``): the state a glide to rest takes over from.
        self.last_goal_v_rad_s: np.ndarray | None = None
        self.last_goal_a_rad_s2: np.ndarray | None = None
        self.last_goal_monotonic_s = -math.inf
        #: Set by the glide to rest that ends a session (:func:`~robogest.backends.rest.go_to_rest`, a control
        #: loop's close): the motion has stopped and only the way to rest is left, so faults already reported
        #: (a servo lost or flagging a hardware error, a health reading past its limit) no longer abort it; one
        #: that did would turn torque off with the arms raised. A lost port still does. Reset by ``connect``.
        self.stopping = False
        self._limits = guard_limits(robot)  # the robot is frozen: build its limit arrays once

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

    def set_control_rate(self, rate_hz: float) -> None:
        """Rate at which goals will be sent, Hz; the guard's per-goal velocity bound and the shutdown ramp use it."""
        rate = float(rate_hz)
        if not (math.isfinite(rate) and rate > 0):
            raise InputError(f"control rate {rate_hz!r} Hz must be a positive finite number")
        self.control_rate_hz = rate

    @property
    def control_period_s(self) -> float:
        """Seconds between goals, ``1 / control_rate_hz``."""
        return 1.0 / self.control_rate_hz

    def write_goal(self, q_rad: np.ndarray, *, source: str = "") -> None:
        """Command joint angles ``(J,)``, radians, after the goal guard (:func:`check_goal`) accepted them.

        A refused goal raises :class:`~robogest.errors.SafetyError` and nothing is written; ``last_goal_rad``
        stays the last goal actually sent, which is where the shutdown ramp to rest starts.
        """
        ref = self._goal_reference()
        q = check_goal(q_rad, self.robot, ref, self.control_period_s, source, self._limits)
        self._send_goal(q)
        v_before = self.last_goal_v_rad_s
        self.last_goal_v_rad_s = (q - ref) / self.control_period_s if self.last_goal_rad is not None else None
        v_now = self.last_goal_v_rad_s
        self.last_goal_a_rad_s2 = None
        if v_before is not None and v_now is not None:
            self.last_goal_a_rad_s2 = (v_now - v_before) / self.control_period_s
        self.last_goal_rad = q.copy()
        self.last_goal_monotonic_s = time.monotonic()

    def confirm_goal(self) -> None:  # noqa: B027 - optional hook
        """Make sure every joint holds the last goal sent (servo backends read it back and re-send it; raise when
        they cannot): called before torque goes on, so no joint drives to an older goal."""

    @abstractmethod
    def _send_goal(self, q_rad: np.ndarray) -> None:
        """Write joint angles ``(J,)``, radians, that the guard accepted (finite, in limits, in speed)."""

    def _connected(self) -> None:
        """Subclasses call this at the end of :meth:`connect`: goals sent before do not count any more."""
        self.last_goal_rad = None
        self.last_goal_v_rad_s = None
        self.last_goal_a_rad_s2 = None
        self.stopping = False

    def _goal_reference(self) -> np.ndarray:
        """The pose the next goal is a step from: the last goal sent; before the first one after connecting, the
        present pose, read now (the robot may have been moved by hand since connect while torque was off)."""
        if self.last_goal_rad is not None:
            return self.last_goal_rad
        return np.array(self.read_positions(), dtype=float)

    @abstractmethod
    def disconnect(self) -> None:
        """Release the port/simulator; must be safe to call twice."""

    def shape_target(self, q_target_rad: np.ndarray, rest_q_rad: np.ndarray) -> np.ndarray:
        """Hook for a health governor, called by the player on every target before limiting.

        Parameters
        ----------
        q_target_rad, rest_q_rad : ndarray [shape=(J,)], radians

        Returns
        -------
        ndarray [shape=(J,)], radians
            The target to command; default: unchanged. Servo backends scale the deviation from rest
            down as the servos heat up (:mod:`robogest.backends.governor`).
        """
        return np.asarray(q_target_rad, float)

    def governor_state(self) -> dict[str, float]:
        """What the health governor is doing (empty when the backend has none)."""
        return {}

    def advance(self, dt_s: float) -> None:  # noqa: B027 - optional hook
        """Advance simulated time; hardware ignores it (the player waits on the clock instead)."""

    def shutdown(self) -> None:
        """Torque off and disconnect. Subclasses that can move to rest first
        (:func:`~robogest.backends.rest.go_to_rest`) override this."""
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
#: Backends by name; each factory takes ``(robot, port=None, baudrate=None, **options)``. Installed packages
#: add more through the ``robogest.backends`` entry-point group.
BACKENDS: Registry[BackendFactory] = Registry("backend", entry_point_group="robogest.backends")
register_backend = BACKENDS.register
backend_names = BACKENDS.names
get_backend_factory = BACKENDS.get
