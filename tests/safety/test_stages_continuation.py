"""A continuation (``track(step0=...)``) that arrives towards an edge too fast brakes into the margin, never past the
hard limits; the streaming planner takes it instead of refusing the utterance."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import SafetyError
from robogest.robot.registry import find_robot
from robogest.safety import JointLimits
from robogest.safety.stages import _brake_step, _stop_distance, check_limits, track


def test_a_continuation_too_fast_for_the_margin_brakes_into_it_and_stays_within_the_hard_limits():
    lim = JointLimits.from_robot(find_robot("humanoid_xl430"))
    dt = 0.02
    a_step = lim.a_max_rad_s2 * dt * dt
    v_step = lim.v_max_rad_s * dt
    q0 = lim.q_min_rad + 0.025  # 5 mrad inside the band's lower edge (margin 0.02)
    step0 = -np.minimum(_brake_step(np.full_like(q0, 0.015), a_step), v_step)  # can stop within 15 mrad, not 5
    reach = _stop_distance(np.abs(step0), a_step)
    assert np.all(reach <= 0.015 + 1e-12) and np.any(reach > 0.005)  # so some joint must brake into the margin
    targets = np.repeat(q0[None], 30, axis=0)
    out = track(targets, lim, dt, q0, step0=step0)  # refused (SafetyError) before
    assert np.all(out >= lim.q_min_rad - 1e-12)
    assert np.all(out >= q0 - reach - 1e-12)
    check_limits(out, lim, dt, np.minimum(q0 - reach, lim.q_min_rad + 0.02), lim.q_max_rad, step0)


def test_stop_distance_is_the_sum_of_the_braking_steps():
    a = np.array([0.3])
    for s in (0.0, 0.2, 0.3, 1.0, 1.05):
        steps, v = [], s
        while v > 0:
            steps.append(v)
            v -= 0.3
        assert _stop_distance(np.array([s]), a)[0] == pytest.approx(sum(steps))


def test_a_continuation_past_the_hard_limit_is_still_refused():
    lim = JointLimits.from_robot(find_robot("humanoid_xl430"))
    dt = 0.02
    q0 = lim.q_min_rad + 1e-4  # at the hard limit, moving out at full speed: no braking keeps it inside
    with pytest.raises(SafetyError, match="position"):
        track(np.repeat(q0[None], 10, axis=0), lim, dt, q0, step0=-lim.v_max_rad_s * dt)
