"""The simulated servo's motion: its own profile (velocity and acceleration registers) holds whatever the goals do,
and it does not depend on how often the bus advances the clock."""

from __future__ import annotations

import numpy as np

from robogest.virtualbus.servo import SimServo
from robogest.virtualbus.tables import MODELS


def moving_servo(accel_units: int, velocity_units: int = 100) -> SimServo:
    s = SimServo(MODELS["XL430-W250"], 1)
    s._store(s.spec.reg("profile_acceleration"), accel_units)
    s._store(s.spec.reg("profile_velocity"), velocity_units)
    s.write(s.spec.reg("torque").addr, b"\x01")
    return s


def drive(s: SimServo, plan: list[tuple[float, int | None]]) -> tuple[np.ndarray, np.ndarray]:
    """Step ``s`` by each ``(dt, new goal or None)``; returns sample times and unrounded positions, ticks."""
    t, ts, ps = 0.0, [0.0], [s.motion.pos]
    for dt, goal in plan:
        if goal is not None:
            s._store(s.spec.reg("goal"), goal)
        s.step(dt)
        t += dt
        ts.append(t)
        ps.append(s.motion.pos)
    return np.array(ts), np.array(ps)


def peak_acceleration(ts: np.ndarray, ps: np.ndarray) -> float:
    v = np.diff(ps) / np.diff(ts)
    return float(np.abs(np.diff(v) / (0.5 * (ts[2:] - ts[:-2]))).max())


def test_a_goal_moved_back_mid_move_is_overshot_within_the_profile_acceleration_not_jumped_to():
    """A goal the servo can no longer stop for (it moved back, or came late) used to be reached by a jump: the
    profile's velocity dropped to 0 at once."""
    s = moving_servo(accel_units=50)
    a_lim = 50 * s.spec.acc_unit_ticks_s2
    start = int(s.motion.pos)
    plan: list[tuple[float, int | None]] = [(0.01, start + 1500)] + [(0.01, None)] * 24
    plan += [(0.01, start + 200)] + [(0.003, None)] * 50 + [(0.15, None)] + [(0.01, None)] * 150
    ts, ps = drive(s, plan)
    assert ps.max() > start + 250  # overshot the goal it could not stop for, then came back
    assert peak_acceleration(ts, ps) <= 1.005 * a_lim
    assert abs(ps[-1] - (start + 200)) < 1.0


def test_motion_does_not_depend_on_how_often_the_bus_advances_the_clock():
    one, many = moving_servo(accel_units=80), moving_servo(accel_units=80)
    goal = int(one.motion.pos) + 900
    drive(one, [(0.12, goal), (0.03, None)])
    drive(many, [(0.001, goal)] + [(0.001, None)] * 149)
    assert abs(one.motion.pos - many.motion.pos) < 1e-6 * goal


def test_without_a_profile_acceleration_the_servo_still_moves_at_once():
    """Profile Acceleration 0 (no limit, as the firmware reads it): the step response of old tests stays."""
    s = moving_servo(accel_units=0, velocity_units=0)
    start = s.motion.pos
    _, ps = drive(s, [(0.01, int(start) + 300)] + [(0.01, None)] * 14)
    assert abs(ps[-1] - (start + 300)) < 2.0  # 300 ticks in 0.15 s
