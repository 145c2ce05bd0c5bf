"""``Trajectory.for_robot``: the one place a trajectory's limit block is copied from a robot."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.robot.registry import find_robot
from robogest.trajectory import Trajectory, check_matches


def test_carries_the_robots_limits_and_passes_check_matches():
    robot = find_robot("desk_arm_sts3215")
    q = np.tile(robot.rest_q_rad, (5, 1))
    traj = Trajectory.for_robot(robot, q, 50.0, audio_path="a.wav")
    check_matches(traj, robot, "t.npz")  # refuses a block that differs from the robot's
    assert traj.robot == robot.name and traj.audio_path == "a.wav" and traj.joint_names == robot.joint_names
    np.testing.assert_array_equal(traj.t_s, np.arange(5) / 50.0)
    np.testing.assert_array_equal(traj.silent, np.zeros(5, bool))
    for key in ("q_min_rad", "q_max_rad", "v_max_rad_s", "a_max_rad_s2", "rest_q_rad"):
        np.testing.assert_array_equal(getattr(traj, key), getattr(robot, key))


def test_times_given_instead_of_a_rate():
    robot = find_robot("desk_arm_sts3215")
    t = np.array([0.0, 0.02, 0.05])
    silent = np.array([False, True, True])
    traj = Trajectory.for_robot(robot, np.tile(robot.rest_q_rad, (3, 1)), t_s=t, silent=silent)
    assert traj.t_s is t and traj.silent is silent
    with pytest.raises(ValueError, match="exactly one of fps and t_s"):
        Trajectory.for_robot(robot, np.tile(robot.rest_q_rad, (3, 1)), 50.0, t_s=t)
