"""Idle motion: subtle, periodic at the configured rates, inside the limits, fading in from rest without a jump."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robogest.errors import InputError
from robogest.live.idle import IdleConfig, IdleMotion
from robogest.retarget import DirectionIK
from robogest.robot.registry import find_robot, list_robots

IDLE = {name: IdleMotion(find_robot(name)) for name in sorted(list_robots())}


@pytest.mark.parametrize("name", sorted(IDLE))
@settings(max_examples=60, deadline=None)
@given(t=st.floats(0.0, 1000.0), start=st.floats(0.0, 100.0))
def test_targets_inside_limits_and_subtle(name, t, start):
    idle = IDLE[name]
    idle.restart(start)
    q = idle.target(t)
    r = idle.robot
    assert (q >= r.q_min_rad).all() and (q <= r.q_max_rad).all()
    assert np.abs(q - np.clip(r.rest_q_rad, idle.lo, idle.hi)).max() <= 2 * idle.config.max_joint_rad + 1e-9


@pytest.mark.parametrize("name", sorted(IDLE))
def test_fades_in_from_rest_and_moves(name):
    idle = IDLE[name]
    idle.restart(10.0)
    rest = np.clip(idle.robot.rest_q_rad, idle.lo, idle.hi)
    np.testing.assert_allclose(idle.target(10.0 + idle.config.delay_s), rest, atol=1e-12)  # at rest until then
    t = 10.0 + np.arange(0, 20, 0.01)
    q = np.array([idle.target(x) for x in t])
    step = np.abs(np.diff(q, axis=0)).max()
    assert step < 0.01  # 10 ms apart: no jump anywhere, fade-in included
    assert np.ptp(q, axis=0).max() > 0.02  # it breathes


def test_breathing_rate_is_the_configured_one():
    idle = IdleMotion(find_robot("humanoid_xl430"), IdleConfig(breaths_per_min=12.0, shift_rad=0.0))
    t = np.arange(0, 60, 1 / idle.fps)
    x = np.array([idle.offset(v) for v in t])
    k = np.argmax(np.abs(x - x.mean(axis=0)).max(axis=0))
    spec = np.abs(np.fft.rfft(x[:, k] - x[:, k].mean()))
    freq = np.fft.rfftfreq(len(t), 1 / idle.fps)
    assert freq[np.argmax(spec)] * 60 == pytest.approx(12.0, abs=0.5)


def test_bad_settings_name_the_fix():
    with pytest.raises(InputError, match="breaths_per_min"):
        IdleConfig(breaths_per_min=100)
    with pytest.raises(InputError, match="subtle"):
        IdleConfig(shift_rad=1.0)


def test_held_joints_never_breathe():
    robot = find_robot("humanoid_xl430")
    joints = [j.model_copy(update={"held": j.name in ("torso_yaw", "l_elbow")}) for j in robot.joints]
    held_robot = robot.model_copy(update={"joints": joints})
    # a retargeter that knows nothing of held joints (a plugin's, say): idle motion still keeps them at rest
    idle = IdleMotion(held_robot, retargeter=DirectionIK(robot))
    robot = held_robot
    q = np.array([idle.target(t) for t in np.arange(0, 20, 0.05)])
    held = robot.held_mask
    assert np.array_equal(q[:, held], np.broadcast_to(robot.rest_q_rad[held], q[:, held].shape))
    assert np.ptp(q[:, ~held], axis=0).max() > 0.02  # the others still do
