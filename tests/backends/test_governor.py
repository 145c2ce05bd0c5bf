"""Health governor: gestures shrink as servos heat up, without jumps; a long monologue ends cooler with it."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.governor import Governor, GovernorConfig
from robogest.backends.player import play
from robogest.virtualbus import ThermalModel, VirtualBus
from robogest.virtualbus.testing import make_robot, monologue

REST = np.zeros(3)


def hot(temperature_c: float) -> Governor:
    g = Governor(GovernorConfig(warn_temperature_c=55.0, max_temperature_c=65.0, min_factor=0.4))
    for sid in (1, 2, 3):
        g.observe(sid, 40.0, 5.0, now_s=0.0)
    g.observe(2, temperature_c, 5.0, now_s=0.0)
    return g


def test_target_factor_falls_from_the_warning_level_to_the_limit():
    assert hot(50.0).target_factor() == 1.0
    assert hot(60.0).target_factor() == 0.7
    assert hot(65.0).target_factor() == hot(90.0).target_factor() == 0.4
    g = hot(40.0)
    g.observe(1, 40.0, 95.0, now_s=60.0)  # strained for a while (load warning at 60 %, limit 100 %)
    assert 0.4 < g.target_factor() < 1.0


def test_cool_servos_leave_targets_alone_and_hot_ones_shrink_gestures():
    q = np.array([0.5, -0.3, 0.2])
    assert np.array_equal(hot(40.0).shape(q, REST, now_s=0.0), q)
    g = hot(62.0)
    for k in range(300):  # during small gestures the factor settles on the target factor
        g.shape(0.2 * q * np.sin(0.1 * k), REST, now_s=0.02 * k)
    out = g.shape(q, REST, now_s=6.0)
    np.testing.assert_allclose(out, 0.58 * q, atol=0.02)
    assert Governor(enabled=False).shape(q, REST).tolist() == q.tolist()


def test_a_new_playback_starts_where_the_robot_is():
    """After a pause the first target passes unchanged (the player holds the present pose before torque on)."""
    g = hot(62.0)
    for k in range(100):
        g.shape(np.full(3, 0.02), REST, now_s=0.02 * k)
    assert g.factor < 0.7
    q_now = np.array([0.5, -0.3, 0.2])
    assert np.array_equal(g.shape(q_now, REST, now_s=10.0), q_now)


def test_hot_rest_is_held_longer():
    g = hot(62.0)
    t = np.arange(0.0, 6.0, 0.02)
    # a gesture back to rest at 2 s, a new one from 2.5 s, both starting and ending at rest
    target = np.where(t < 2.0, 0.4 * np.sin(np.pi * t), np.where(t >= 2.5, 0.4 * np.sin(np.pi * (t - 2.5)), 0.0))
    out = np.array([g.shape(np.full(3, x), REST, now_s=s)[0] for x, s in zip(target, t, strict=True)])
    moving_in, moving_out = np.abs(target[t >= 2.5]) > 0.02, np.abs(out[t >= 2.5]) > 0.02
    assert g.holds >= 1 and moving_out.any()
    assert np.argmax(moving_out) > np.argmax(moving_in) + 10  # stays at rest > 0.2 s longer


@settings(max_examples=60, deadline=None)
@given(
    temps=st.lists(st.floats(30.0, 80.0), min_size=1, max_size=5),
    steps=st.lists(st.floats(-0.05, 0.05), min_size=5, max_size=120),
)
def test_shaping_never_makes_a_target_jump(temps, steps):
    """|Δout| <= |Δin| (1 + max_rate dt) + extra_speed dt: a changing factor adds only a small, bounded speed."""
    cfg = GovernorConfig()
    g = Governor(cfg)
    dt = 0.02
    q, prev_out, prev_q = np.zeros(2), None, None
    for k, step in enumerate(steps):
        if k < len(temps):
            g.observe(1, temps[k], 10.0, now_s=k * dt)
        q = np.clip(q + step, -1.5, 1.5)
        out = g.shape(q, np.zeros(2), now_s=k * dt)
        if prev_out is not None:
            bound = np.max(np.abs(q - prev_q)) * (1 + cfg.max_rate_per_s * dt) + cfg.extra_speed_rad_s * dt
            assert np.max(np.abs(out - prev_out)) <= bound + 1e-12
        assert np.all(np.abs(out) <= np.abs(q) + 1e-12)  # never further from rest than asked
        prev_out, prev_q = out, q


def test_long_monologue_ends_cooler_with_the_governor(tmp_path):
    """8 s of gestures in real time (the limiter keeps the robot's speed limits, so a faster replay would not heat
    more), servos heating 30x faster than real (2 min time constant)."""
    robot = make_robot(tmp_path, family="feetech", protocol=0.0, n_joints=2)
    thermal = ThermalModel(rise_c_at_full_load=1500.0, tau_s=120.0, time_scale=30.0)
    final, states = {}, {}
    for governed in (False, True):
        with VirtualBus(robot, thermal=thermal) as bus:
            backend = get_backend_factory("feetech")(
                robot, port=bus.port, governor=governed, warn_temperature_c=33.0, max_temperature_c=80.0, health_hz=4
            )
            report = play(monologue(robot, 8.0), backend)
            assert report.completed, report.errors
            final[governed] = max(s.motion.temp_c for s in bus.servos)
            states[governed] = backend.governor_state()
    assert final[True] < final[False] - 4.0, final  # measured: ~45 vs ~55.5 °C through the ControlLoop
    assert states[False]["lowest_factor"] == 1.0
    assert states[True]["lowest_factor"] < 0.95 and states[True]["lengthened_rests"] >= 1


def test_current_sensing_servos_do_not_feed_load_to_the_governor(tmp_path):
    """XM430/XL330 hold Present Current (mA units) where XL430 holds Present Load (0.1 %)."""
    g = hot(40.0)
    g.observe(1, 40.0, None, now_s=60.0)
    assert g.target_factor() == 1.0 and 1 in g.temperatures_c
    robot = make_robot(tmp_path, model="XM430-W350", n_joints=1)
    xm = get_backend_factory("dynamixel")(robot, port="/dev/null")
    assert not xm._load_is_percent(0)
    xl = get_backend_factory("dynamixel")(make_robot(tmp_path / "xl", n_joints=1), port="/dev/null")
    assert xl._load_is_percent(0)
