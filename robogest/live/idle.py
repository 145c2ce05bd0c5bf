"""Idle motion: breathing and a slow weight shift while the robot listens, so it does not look switched off.

NAOqi's animated speech breathes at about 12 breaths/min when not speaking; the Reachy Mini conversation app
starts breathing about 0.3 s after speech stops. Both are authored here on the canonical human skeleton
(spine, shoulders, head) and retargeted once at session start with the robot's own IK, so any robot
definition gets a motion that its retargeting understands. Each cycle is tabulated in joint space as an
offset from the retargeted rest pose; :meth:`IdleMotion.target` sums the two periodic offsets, scales them by
a fade envelope and clamps the result inside the position limits. The control loop's online limiter keeps
velocity, acceleration and jerk within limits whatever the target does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from robogest.generators.poses import DOF, N_DOF, dofs_to_rotations
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL_PELVIS_HEIGHT_M
from robogest.robot.config import RobotConfig

if TYPE_CHECKING:
    from robogest.retarget.base import Retargeter  # the package imports mujoco: only the IK needs it, and lazily


@dataclass(frozen=True)
class IdleConfig:
    """Idle motion settings.

    Attributes
    ----------
    breaths_per_min : float
        Breathing rate, 1/min (12, NAOqi's idle breathing).
    breath_rad : float
        Breathing amplitude on the canonical skeleton (spine pitch, shoulder shrug), radians.
    shift_period_s : float
        Period of the slow weight shift (spine roll/yaw, head counter-motion), seconds.
    shift_rad : float
        Weight-shift amplitude, radians.
    delay_s : float
        Idle motion starts this long after speech stops, seconds (0.3, the Reachy Mini app).
    fade_s : float
        Its amplitude fades in over this long, seconds, so leaving speech or rest never jumps.
    max_joint_rad : float
        Largest offset from rest of any joint per cycle, radians (each joint's cycle is scaled down to it).
    """

    breaths_per_min: float = 12.0
    breath_rad: float = 0.04
    shift_period_s: float = 14.0
    shift_rad: float = 0.05
    delay_s: float = 0.3
    fade_s: float = 1.5
    max_joint_rad: float = 0.08

    def __post_init__(self) -> None:
        from robogest.errors import InputError

        if not 2.0 <= self.breaths_per_min <= 40.0:
            raise InputError(f"idle: breaths_per_min {self.breaths_per_min} must lie in [2, 40]")
        if not 2.0 <= self.shift_period_s <= 120.0:
            raise InputError(f"idle: shift_period_s {self.shift_period_s} must lie in [2, 120] s")
        if not (0.0 <= self.breath_rad <= 0.2 and 0.0 <= self.shift_rad <= 0.2):
            raise InputError("idle: breath_rad and shift_rad must lie in [0, 0.2] rad (idle motion is subtle)")
        if not 0.0 < self.max_joint_rad <= 0.3:
            raise InputError(f"idle: max_joint_rad {self.max_joint_rad} must lie in (0, 0.3] rad")
        if self.delay_s < 0 or self.fade_s <= 0:
            raise InputError("idle: delay_s must be >= 0 and fade_s > 0")


def _cycle(kind: str, cfg: IdleConfig, fps: float) -> tuple[np.ndarray, float]:
    """One period of canonical DOFs ``(T, D)`` radians, and its period in seconds."""
    if kind == "breath":
        period = 60.0 / cfg.breaths_per_min
        t = np.arange(round(period * fps)) / fps
        # Inhale is a little shorter than exhale: a raised-cosine on a warped phase.
        ph = 2 * np.pi * t / period
        s = 0.5 - 0.5 * np.cos(ph + 0.35 * np.sin(ph))
        d = np.zeros((len(t), N_DOF))
        d[:, DOF["spine_pitch"]] = -0.5 * cfg.breath_rad * s  # chest rises: a slight lean back
        d[:, DOF["head_pitch"]] = 0.3 * cfg.breath_rad * s  # the head keeps its gaze
        d[:, DOF["l_shrug"]] = d[:, DOF["r_shrug"]] = cfg.breath_rad * s
        d[:, DOF["l_abd"]] = d[:, DOF["r_abd"]] = 0.5 * cfg.breath_rad * s
        return d, period
    period = cfg.shift_period_s
    t = np.arange(round(period * fps)) / fps
    ph = 2 * np.pi * t / period
    d = np.zeros((len(t), N_DOF))
    d[:, DOF["spine_roll"]] = cfg.shift_rad * np.sin(ph)
    d[:, DOF["spine_yaw"]] = 0.6 * cfg.shift_rad * np.sin(ph + 0.8)
    d[:, DOF["head_roll"]] = -0.6 * cfg.shift_rad * np.sin(ph)  # the head stays level
    d[:, DOF["head_yaw"]] = 0.8 * cfg.shift_rad * np.sin(2 * ph + 0.3)  # a glance now and then
    d[:, DOF["l_flex"]] = 0.4 * cfg.shift_rad * np.sin(ph + 1.3)
    d[:, DOF["r_flex"]] = -0.4 * cfg.shift_rad * np.sin(ph + 1.3)
    return d, period


class IdleMotion:
    """Breathing + weight shift for one robot, as joint targets ``(J,)`` radians (see module docstring).

    Parameters
    ----------
    robot : RobotConfig
    config : IdleConfig
    retargeter : Retargeter, optional
        The session's IK (built when omitted).
    fps : float
        Tabulation rate of the cycles, frames/s.
    """

    def __init__(
        self,
        robot: RobotConfig,
        config: IdleConfig | None = None,
        retargeter: Retargeter | None = None,
        fps: float = 25.0,
    ) -> None:
        from robogest.retarget import DirectionIK

        self.config = config or IdleConfig()
        self.robot = robot
        ik = retargeter or DirectionIK(robot)
        self.fps = float(fps)
        self.rest_q_rad = np.asarray(robot.rest_q_rad, float)
        self._tables: list[tuple[np.ndarray, float]] = []
        for kind in ("breath", "shift"):
            dofs, period = _cycle(kind, self.config, self.fps)
            rest = ik.retarget(self._motion(np.zeros((2, N_DOF))), q0=self.rest_q_rad).q_rad[-1]
            q = ik.retarget(self._motion(np.concatenate([dofs, dofs])), q0=rest).q_rad[len(dofs) :]  # settled
            off = q - rest  # (T, J) offsets from the retargeted rest
            # Near a singular pose (a desk arm pointing straight up) a small human motion can swing a joint far:
            # idle motion stays subtle on every joint.
            peak = np.abs(off).max(axis=0)
            off *= np.minimum(1.0, self.config.max_joint_rad / np.maximum(peak, 1e-12))
            off[:, robot.held_mask] = 0.0  # held joints (legs) never breathe
            self._tables.append((off, period))
        # a held joint's band is its angle (the margin would otherwise pull one held near a limit off it)
        self.lo = np.where(robot.held_mask, self.rest_q_rad, robot.q_min_rad + 0.03)
        self.hi = np.where(robot.held_mask, self.rest_q_rad, robot.q_max_rad - 0.03)
        self.started_s = 0.0  # envelope origin (loop seconds)
        self.stop_s: float | None = None  # fade-out origin (loop seconds), set when speech is coming
        self.fade_out_s = 0.12

    def _motion(self, dofs: np.ndarray) -> HumanMotion:
        root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (len(dofs), 1))
        return HumanMotion(fps=self.fps, rotations=dofs_to_rotations(dofs), root_pos_m=root)

    def restart(self, t_s: float) -> None:
        """Speech stopped (or rest was reached) at loop time ``t_s``: fade in again from zero after the delay."""
        self.started_s = float(t_s)
        self.stop_s = None

    def stop(self, t_s: float) -> None:
        """Speech is coming: fade out over ``fade_out_s`` from loop time ``t_s``, so the robot is at rest and still
        when the utterance starts (it would otherwise first glide there, delaying the speech)."""
        if self.stop_s is None:
            self.stop_s = float(t_s)

    def envelope(self, t_s: float) -> float:
        """Amplitude in [0, 1] at loop time ``t_s``: 0 until ``delay_s``, then a minimum-jerk fade-in."""
        x = (t_s - self.started_s - self.config.delay_s) / self.config.fade_s
        x = min(1.0, max(0.0, x))
        env = x**3 * (10 - 15 * x + 6 * x * x)
        if self.stop_s is not None:
            y = min(1.0, max(0.0, (t_s - self.stop_s) / self.fade_out_s))
            env *= 1.0 - y**3 * (10 - 15 * y + 6 * y * y)
        return env

    def offset(self, t_s: float) -> np.ndarray:
        """Un-faded offset from rest ``(J,)`` radians at ``t_s`` (periodic, linear between table frames)."""
        out = np.zeros_like(self.rest_q_rad)
        for table, period in self._tables:
            x = (t_s % period) * self.fps
            i = int(x) % len(table)
            f = x - int(x)
            out += (1 - f) * table[i] + f * table[(i + 1) % len(table)]
        return out

    def target(self, t_s: float) -> np.ndarray:
        """Idle target ``(J,)`` radians at loop time ``t_s``, inside the position limits."""
        return np.clip(self.rest_q_rad + self.envelope(t_s) * self.offset(t_s), self.lo, self.hi)

    __call__ = target
