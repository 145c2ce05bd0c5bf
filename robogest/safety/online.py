"""Online limiter: the last safety stage before a backend, run once per control tick.

:class:`OnlineLimiter` turns any stream of target poses (a trajectory sampled at the loop's time, an idle
motion, the rest pose) into goals that respect per-joint position, velocity, acceleration **and jerk** limits
at the control rate actually used, whatever rate the targets were made at. Each tick it asks `ruckig`_
(time-optimal, jerk-limited online trajectory generation) for the move from its state to the target and takes
the state one control period along it.

Why the limits hold on what reaches the bus: the goals are samples, one period apart, of one continuous
trajectory whose velocity, acceleration and jerk stay within the limits (each tick continues from the
position, velocity and acceleration reached by the previous one). A finite difference of such samples is a
weighted mean of the continuous derivative, so ``|Δq|/T ≤ v_max``, ``|Δ²q|/T² ≤ a_max`` and
``|Δ³q|/T³ ≤ j_max`` hold at the playback period ``T`` (up to floating-point rounding; internally the limits
are shrunk by 1e-6 relative to absorb it).

Positions are guaranteed here, not only upstream (ruckig's community edition does not enforce them): targets
are clamped into ``[q_min + margin, q_max − margin]`` (widened to include rest) and a joint's candidate state is
taken only if braking from it (as hard as the limits allow) stops inside ``[q_min, q_max]``. Otherwise that
joint brakes from its present state, which the same check accepted one tick earlier, so the braking path stays
inside (induction; joints are planned independently, so one joint braking leaves the others alone). If ruckig
fails to compute a brake the joints hold the last goal (counted in ``fallbacks``); they never jump.

Tracking: trajectories made offline use the whole acceleration limit with instant switches (bang-bang), which
no jerk-limited follower can match; planning time-optimally to match their full velocity then overshoots by tens
of degrees after every lag (measured: 50° on the demo sentence). The limiter therefore plans towards the target in
the target's moving frame with only :data:`VELOCITY_FEEDFORWARD` of its velocity, and the control loop samples
the trajectory :data:`LOOKAHEAD_S` ahead, which makes up the lag. Goal vs trajectory on the demo sentence
(humanoid_xl430, 25–100 Hz): 0.85° RMS, 6–11° max; on the smooth sine test 0.7–1.6° RMS (both tuned there).

The state is the last goal actually sent: :meth:`OnlineLimiter.propose` computes the next goal and
:meth:`OnlineLimiter.commit` adopts it once the backend accepted it, so a failed write or a late tick never
makes the next goal jump.

.. _ruckig: https://github.com/pantor/ruckig
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ruckig

from robogest.errors import InputError
from robogest.robot.config import LIMIT_MARGIN_RAD, RobotConfig

#: Limits given to ruckig are shrunk by this factor so rounding never shows as a violation.
_SHRINK = 1.0 - 1e-6
#: A target velocity is capped at this fraction of the velocity limit (room to catch up with it).
_TARGET_V_FRACTION = 0.98
#: Fraction of a target's velocity the limiter plans to match (see "Tracking" in the module docstring).
VELOCITY_FEEDFORWARD = 0.25
#: How far ahead of the loop time a control loop samples a trajectory, seconds (see "Tracking").
LOOKAHEAD_S = 0.075
_OK = (ruckig.Result.Working, ruckig.Result.Finished)
#: Ruckig's exception (its own class since 0.19, not a RuntimeError), and the two this code caught before it.
_RUCKIG_ERRORS = (ruckig.RuckigError, RuntimeError, ValueError)
#: On a refused input, ruckig is asked once more with acceleration and jerk limits this much lower (relative).
_NUDGE = 1e-9


@dataclass(frozen=True, eq=False)
class MotionState:
    """Position ``(J,)`` rad, velocity ``(J,)`` rad/s and acceleration ``(J,)`` rad/s² of the goal stream."""

    q_rad: np.ndarray
    v_rad_s: np.ndarray
    a_rad_s2: np.ndarray


#: Below this (rad, rad/s, rad/s²) a state is taken to have arrived on a still target: float rounding only.
_ARRIVED_TOL = 1e-9


class OnlineLimiter:
    """Per-joint position, velocity, acceleration and jerk limiter for one control loop.

    Parameters
    ----------
    q_min_rad, q_max_rad : ndarray [shape=(J,)], radians
        Hard position limits; goals never leave them.
    v_max_rad_s : ndarray [shape=(J,)], rad/s
    a_max_rad_s2 : ndarray [shape=(J,)], rad/s²
    j_max_rad_s3 : ndarray [shape=(J,)], rad/s³
    period_s : float, seconds
        Control period: one :meth:`propose` moves the state this far along.
    q0_rad : ndarray [shape=(J,)], radians
        Starting pose (taken to be still); clipped into the hard limits.
    rest_q_rad : ndarray [shape=(J,)], radians, optional
        Rest pose: always a valid target even when it lies inside the margin.
    margin_rad : float, radians
        Targets are clamped this far inside the hard limits.
    held_mask : ndarray [shape=(J,)], bool, optional
        Joints held at rest (needs ``rest_q_rad``): their target is always rest, so once there they never leave it
        (one found elsewhere at start glides onto it).
    """

    def __init__(
        self,
        q_min_rad: np.ndarray,
        q_max_rad: np.ndarray,
        v_max_rad_s: np.ndarray,
        a_max_rad_s2: np.ndarray,
        j_max_rad_s3: np.ndarray,
        period_s: float,
        q0_rad: np.ndarray,
        *,
        rest_q_rad: np.ndarray | None = None,
        margin_rad: float = LIMIT_MARGIN_RAD,
        stop_within_s: float | None = None,
        held_mask: np.ndarray | None = None,
    ) -> None:
        arrays = [np.array(a, dtype=float) for a in (q_min_rad, q_max_rad, v_max_rad_s, a_max_rad_s2, j_max_rad_s3)]
        n = arrays[0].size
        if any(a.shape != (n,) for a in arrays) or n == 0:
            raise InputError("OnlineLimiter: limits must be non-empty 1-D arrays of one length (one per joint)")
        if not all(np.all(np.isfinite(a)) for a in arrays) or np.any(arrays[0] >= arrays[1]):
            raise InputError("OnlineLimiter: limits must be finite with q_min_rad < q_max_rad")
        if any(np.any(a <= 0) for a in arrays[2:]) or not (np.isfinite(period_s) and period_s > 0):
            raise InputError("OnlineLimiter: velocity, acceleration, jerk limits and period_s must be > 0")
        self.q_min_rad, self.q_max_rad, self.v_max_rad_s, self.a_max_rad_s2, self.j_max_rad_s3 = arrays
        self.n_joints = n
        self.period_s = float(period_s)
        rest = None if rest_q_rad is None else np.clip(np.asarray(rest_q_rad, float), arrays[0], arrays[1])
        self.rest_q_rad = rest
        lo, hi = self.q_min_rad + margin_rad, self.q_max_rad - margin_rad
        mid = 0.5 * (self.q_min_rad + self.q_max_rad)
        lo, hi = np.where(lo > hi, mid, lo), np.where(lo > hi, mid, hi)
        if rest is not None:
            lo, hi = np.minimum(lo, rest), np.maximum(hi, rest)
        if held_mask is not None and np.any(held_mask):
            held = np.asarray(held_mask, dtype=bool)
            if rest is None or held.shape != (n,):
                raise InputError(f"OnlineLimiter: held_mask needs a rest pose and shape ({n},), got {held.shape}")
            lo, hi = np.where(held, rest, lo), np.where(held, rest, hi)
        self._otg = ruckig.Ruckig(n)
        self._traj = ruckig.Trajectory(n)
        self._inp = self._input(ruckig.ControlInterface.Position)
        self._brake_inp = self._input(ruckig.ControlInterface.Velocity)
        self._still_inp = self._input(ruckig.ControlInterface.Position)  # durations to standing still somewhere
        self._still_traj = ruckig.Trajectory(n)
        self.stop_within_s = None if stop_within_s is None else float(stop_within_s)
        if self.stop_within_s is not None:
            if rest is None or not (np.isfinite(self.stop_within_s) and self.stop_within_s > 2 * self.period_s):
                raise InputError(
                    f"OnlineLimiter: stop_within_s {stop_within_s} needs a rest pose and more than two periods"
                )
            reach = self.reach_rad(self.stop_within_s) * 0.98
            lo, hi = np.maximum(lo, np.minimum(rest, rest - reach)), np.minimum(hi, np.maximum(rest, rest + reach))
        self.band_lo_rad, self.band_hi_rad = lo, hi
        self.fallbacks = 0  #: ticks where a brake could not be computed and the last goal was held
        self.brakes = 0  #: ticks where a joint's candidate was refused by the braking check and that joint braked
        self.envelope_ticks = 0  #: ticks where a joint turned towards rest to stay within stop_within_s of it
        self.reset(q0_rad)

    @classmethod
    def for_robot(
        cls,
        robot: RobotConfig,
        period_s: float,
        q0_rad: np.ndarray,
        *,
        margin_rad: float = LIMIT_MARGIN_RAD,
        stop_within_s: float | None = None,
    ) -> OnlineLimiter:
        """The limiter for a :class:`~robogest.robot.config.RobotConfig` (its limits, jerk limits and rest)."""
        return cls(
            robot.q_min_rad, robot.q_max_rad, robot.v_max_rad_s, robot.a_max_rad_s2, robot.j_max_rad_s3,
            period_s, q0_rad, rest_q_rad=robot.rest_q_rad, margin_rad=margin_rad, stop_within_s=stop_within_s,
            held_mask=robot.held_mask,
        )  # fmt: skip

    def reach_rad(self, t_s: float) -> np.ndarray:
        """Per joint ``(J,)`` radians: the farthest a joint can get from a standstill and be still again within
        ``t_s`` seconds (bisection on ruckig's time-optimal durations)."""
        lo, hi = np.zeros(self.n_joints), self.q_max_rad - self.q_min_rad
        z = np.zeros(self.n_joints)
        still = MotionState(z, z, z)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            d = self._min_durations_s(still, mid)
            fits = d <= t_s if d is not None else np.zeros(self.n_joints, bool)
            lo, hi = np.where(fits, mid, lo), np.where(fits, hi, mid)
        return lo

    def _input(self, interface: ruckig.ControlInterface) -> ruckig.InputParameter:
        inp = ruckig.InputParameter(self.n_joints)
        inp.control_interface = interface
        inp.synchronization = ruckig.Synchronization.No  # every joint as fast as its own limits allow
        inp.max_velocity = (self.v_max_rad_s * _SHRINK).tolist()
        inp.max_acceleration = (self.a_max_rad_s2 * _SHRINK).tolist()
        inp.max_jerk = (self.j_max_rad_s3 * _SHRINK).tolist()
        inp.target_acceleration = [0.0] * self.n_joints
        inp.target_velocity = [0.0] * self.n_joints
        inp.target_position = [0.0] * self.n_joints
        return inp

    # --- state -------------------------------------------------------------------------------------
    def reset(self, q0_rad: np.ndarray) -> None:
        """Start over from ``q0_rad`` ``(J,)``, standing still (clipped into the hard limits)."""
        q0 = np.asarray(q0_rad, dtype=float)
        if q0.shape != (self.n_joints,) or not np.all(np.isfinite(q0)):
            raise InputError(f"OnlineLimiter: start pose must be {self.n_joints} finite angles, got {q0}")
        z = np.zeros(self.n_joints)
        self.state = MotionState(np.clip(q0, self.q_min_rad, self.q_max_rad), z, z.copy())
        self._proposed: MotionState | None = None
        self._target = self.state.q_rad.copy()

    def take_over(self, q_rad: np.ndarray, v_rad_s: np.ndarray, a_rad_s2: np.ndarray) -> np.ndarray:
        """Start over from a goal stream that is moving: pose ``q_rad``, velocity ``v_rad_s`` and acceleration
        ``a_rad_s2``, each ``(J,)`` (rad, rad/s, rad/s²), where the limiter can carry that motion on within every
        limit: acceleration within its limit, velocity that stays within its limit as the acceleration is brought
        to zero at the jerk limit, and a hardest brake that stays within the position limits. A joint where it
        cannot (an erratic stream, say) starts still, as :meth:`reset` does. Returns ``(J,)`` bool: taken over."""
        self.reset(q_rad)
        v = np.nan_to_num(np.asarray(v_rad_s, dtype=float), nan=np.inf)
        a = np.nan_to_num(np.asarray(a_rad_s2, dtype=float), nan=np.inf)
        ok = (np.abs(a) <= self.a_max_rad_s2) & (
            np.abs(v + a * np.abs(a) / (2 * self.j_max_rad_s3)) <= self.v_max_rad_s
        )
        ok &= np.abs(v) <= self.v_max_rad_s
        cand = MotionState(self.state.q_rad, np.where(ok, v, 0.0), np.where(ok, a, 0.0))
        ok &= self._stops_inside(cand)
        self.state = MotionState(self.state.q_rad, np.where(ok, v, 0.0), np.where(ok, a, 0.0))
        return np.asarray(ok, dtype=bool)

    @property
    def q_rad(self) -> np.ndarray:
        """Last committed goal ``(J,)``, radians."""
        return self.state.q_rad

    def clamp_target(self, q_rad: np.ndarray) -> np.ndarray:
        """``q_rad`` ``(J,)`` clamped into the target band ``[q_min + margin, q_max − margin]`` ∪ rest (and, with
        ``stop_within_s``, to the poses from which rest can be reached in that time)."""
        return np.asarray(np.clip(np.asarray(q_rad, dtype=float), self.band_lo_rad, self.band_hi_rad), dtype=float)

    @property
    def still(self) -> bool:
        """True when velocity and acceleration are zero (to 1e-6)."""
        return bool(np.max(np.abs(self.state.v_rad_s)) <= 1e-6 and np.max(np.abs(self.state.a_rad_s2)) <= 1e-6)

    def settled(self, tol_rad: float = 1e-6) -> bool:
        """True when the state sits still on the last target (within ``tol_rad``)."""
        return self.still and bool(np.max(np.abs(self.state.q_rad - self._target)) <= tol_rad)

    def time_to_reach_s(self, target_q_rad: np.ndarray) -> float:
        """Shortest time, seconds, from the present state to standing still on ``target_q_rad`` ``(J,)`` within every
        limit: the time-optimal bound (each joint on its own, the slowest counts) that no follower can beat, e.g.
        for judging how fast an interrupt reaches rest."""
        d = self._min_durations_s(self.state, self.clamp_target(np.asarray(target_q_rad, dtype=float)))
        if d is None:
            raise InputError("OnlineLimiter: ruckig found no motion to the target from the present state")
        return float(d.max())

    # --- one tick ----------------------------------------------------------------------------------
    def propose(self, target_q_rad: np.ndarray, target_v_rad_s: np.ndarray | None = None) -> np.ndarray:
        """Next goal ``(J,)`` rad towards ``target_q_rad`` ``(J,)`` (moving at ``target_v_rad_s``, rad/s, if given).

        Not adopted until :meth:`commit`; calling ``propose`` again recomputes from the same state.
        A NaN/inf target is refused by braking (never commanded).
        """
        tq = np.asarray(target_q_rad, dtype=float)
        if tq.shape != (self.n_joints,):
            raise InputError(f"OnlineLimiter: target has shape {tq.shape}; expected ({self.n_joints},)")
        s = self.state
        cand = None
        if np.all(np.isfinite(tq)):
            goal = self.clamp_target(tq)
            tv = np.zeros(self.n_joints)
            if target_v_rad_s is not None:
                tv = np.nan_to_num(np.asarray(target_v_rad_s, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
                cap = _TARGET_V_FRACTION * self.v_max_rad_s
                tv = VELOCITY_FEEDFORWARD * np.where(goal == tq, np.clip(tv, -cap, cap), 0.0)  # clamped: still
            self._target = goal
            cand = self._follow(s, goal, tv)
            if cand is not None and self.stop_within_s is not None:
                cand = self._keep_rest_within_reach(s, cand)
        ok = self._stops_inside(cand) if cand is not None else np.zeros(self.n_joints, dtype=bool)
        if cand is None or not ok.all():  # joints are independent: only those that could not stop inside brake
            brake = self._brake(s)
            if cand is None:
                cand = brake
            else:
                cand = MotionState(
                    np.where(ok, cand.q_rad, brake.q_rad),
                    np.where(ok, cand.v_rad_s, brake.v_rad_s),
                    np.where(ok, cand.a_rad_s2, brake.a_rad_s2),
                )
        self._proposed = cand
        return np.array(cand.q_rad, dtype=float)

    def commit(self) -> None:
        """Adopt the last proposed goal: it was sent."""
        if self._proposed is not None:
            self.state = self._proposed
            self._proposed = None

    def step(self, target_q_rad: np.ndarray, target_v_rad_s: np.ndarray | None = None) -> np.ndarray:
        """:meth:`propose` then :meth:`commit` (for callers whose send cannot fail)."""
        q = self.propose(target_q_rad, target_v_rad_s)
        self.commit()
        return q

    def _follow(self, s: MotionState, goal: np.ndarray, tv: np.ndarray) -> MotionState | None:
        """One period towards a target at ``goal`` moving at constant velocity ``tv``, planned in the target's frame.

        Relative to the moving target the problem is a plain move to (0, 0, 0) with the velocity bounds shifted by
        ``tv`` (so the absolute velocity stays within ±v_max); acceleration and jerk are the same in both frames.
        Planning to a fixed point instead would make the limiter slow down to "arrive" at where the target was.
        """
        inp = self._inp
        inp.current_position = (s.q_rad - goal).tolist()
        inp.current_velocity = (s.v_rad_s - tv).tolist()
        inp.current_acceleration = s.a_rad_s2.tolist()
        v = self.v_max_rad_s * _SHRINK
        inp.max_velocity = (v - tv).tolist()
        inp.min_velocity = (-v - tv).tolist()
        rel = self._advance(inp)
        if rel is None:
            return None
        t = self.period_s
        # Arrived (to float rounding) on a still target: land on it exactly, so "at rest" means equal to rest.
        arrived = (tv == 0) & (np.abs(rel.q_rad) < _ARRIVED_TOL) & (np.abs(rel.v_rad_s) < _ARRIVED_TOL)
        arrived &= np.abs(rel.a_rad_s2) < _ARRIVED_TOL
        q = np.where(arrived, goal, rel.q_rad + goal + tv * t)
        return MotionState(q, np.where(arrived, 0.0, rel.v_rad_s + tv), np.where(arrived, 0.0, rel.a_rad_s2))

    def _calculate(self, inp: ruckig.InputParameter, traj: ruckig.Trajectory) -> bool:
        """Plan ``inp`` into ``traj``; False when ruckig cannot.

        Ruckig's step 1 finds no profile on some inputs that sit exactly on the boundary between two
        profile shapes (found by hypothesis: a rest-to-rest move whose acceleration just reaches its
        limit as the velocity does). Limits a hair lower move it off that boundary and stay safe.
        """
        try:
            return self._otg.calculate(inp, traj) in _OK
        except _RUCKIG_ERRORS:
            pass
        a, j = inp.max_acceleration, inp.max_jerk
        inp.max_acceleration = [x * (1.0 - _NUDGE) for x in a]
        inp.max_jerk = [x * (1.0 - _NUDGE) for x in j]
        try:
            return self._otg.calculate(inp, traj) in _OK
        except _RUCKIG_ERRORS:
            return False
        finally:
            inp.max_acceleration, inp.max_jerk = a, j

    def _advance(self, inp: ruckig.InputParameter) -> MotionState | None:
        if not self._calculate(inp, self._traj):
            return None
        q, v, a = self._traj.at_time(self.period_s)
        out = MotionState(np.array(q), np.array(v), np.array(a))
        finite = all(np.all(np.isfinite(x)) for x in (out.q_rad, out.v_rad_s, out.a_rad_s2))
        return out if finite else None

    def _min_durations_s(self, s: MotionState, target_q_rad: np.ndarray) -> np.ndarray | None:
        """Per joint ``(J,)``: shortest time from ``s`` to standing still on ``target_q_rad``, seconds (each joint on
        its own, every limit kept); None if ruckig cannot compute it."""
        inp = self._still_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = _lists(s)
        inp.target_position = np.asarray(target_q_rad, dtype=float).tolist()
        if not self._calculate(inp, self._still_traj):
            return None
        return np.asarray(self._still_traj.independent_min_durations)

    def _keep_rest_within_reach(self, s: MotionState, cand: MotionState) -> MotionState:
        """Joints whose candidate could not be at rest within ``stop_within_s`` take the time-optimal step towards
        rest instead. From a state within reach that step stays within reach (the rest of a time-optimal motion
        is time-optimal), so an interrupt is at rest within ``stop_within_s`` from every goal (induction)."""
        rest, within_s = self.rest_q_rad, self.stop_within_s
        if rest is None or within_s is None:  # only called with stop_within_s, which needs a rest pose
            return cand
        t = self._min_durations_s(cand, rest)
        far = np.ones(self.n_joints, bool) if t is None else t > within_s + 1e-9
        if not far.any():
            return cand
        home = self._follow(s, rest, np.zeros(self.n_joints))
        if home is None:
            return cand  # the braking check that follows still keeps the limits
        self.envelope_ticks += 1
        return MotionState(
            np.where(far, home.q_rad, cand.q_rad), np.where(far, home.v_rad_s, cand.v_rad_s),
            np.where(far, home.a_rad_s2, cand.a_rad_s2),
        )  # fmt: skip

    def _stops_inside(self, s: MotionState) -> np.ndarray:
        """Per joint ``(J,)`` bool: does braking from ``s`` as hard as the limits allow stay within the limits?"""
        inside = (s.q_rad >= self.q_min_rad) & (s.q_rad <= self.q_max_rad)
        inp = self._brake_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = _lists(s)
        if not self._calculate(inp, self._traj):
            return np.zeros(self.n_joints, dtype=bool)
        ext = self._traj.position_extrema
        lo = np.array([e.min for e in ext])
        hi = np.array([e.max for e in ext])
        return inside & (lo >= self.q_min_rad) & (hi <= self.q_max_rad)

    def _brake(self, s: MotionState) -> MotionState:
        """One period along the hardest permitted brake from ``s``; hold ``s`` if even that cannot be computed."""
        self.brakes += 1
        inp = self._brake_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = _lists(s)
        out = self._advance(inp)
        if out is None:
            self.fallbacks += 1
            z = np.zeros(self.n_joints)
            return MotionState(s.q_rad.copy(), z, z.copy())
        out = MotionState(np.clip(out.q_rad, self.q_min_rad, self.q_max_rad), out.v_rad_s, out.a_rad_s2)
        return out


def _lists(s: MotionState) -> tuple[list[float], list[float], list[float]]:
    return s.q_rad.tolist(), s.v_rad_s.tolist(), s.a_rad_s2.tolist()
