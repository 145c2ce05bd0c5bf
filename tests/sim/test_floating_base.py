"""A floating-base humanoid (free joint on the pelvis, as menagerie models have) stands in the simulator: the one
MJCF loader welds its base at standing height, so it neither falls nor sinks, and its held legs never move."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robogest.backends.control import ControlLoop
from robogest.backends.mujoco_sim import MujocoBackend
from robogest.robot.config import load_robot_config
from robogest.robot.mjcf import load_mjcf
from tests.robots.humanoid_fixture import LEGS, STAND_HEIGHT_M, write_humanoid


def _sole_bottoms_z(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """World z of the two soles' lowest faces (boxes, 0.02 m half-height, level at rest)."""
    ids = [m.geom("l_sole").id, m.geom("r_sole").id]
    return d.geom_xpos[ids, 2] - m.geom_size[ids, 2]


@pytest.mark.parametrize("home", [True, False], ids=["home_key", "no_key"])
def test_the_free_joint_is_welded_with_the_feet_on_the_floor(tmp_path, home):
    """From the home keyframe's base pose when there is one, else lowered from the MJCF's 0.9 m until the lowest
    point touches the floor."""
    robot = load_robot_config(write_humanoid(tmp_path, home=home))
    m = load_mjcf(robot)
    assert not (m.jnt_type == mujoco.mjtJoint.mjJNT_FREE).any() and m.nq == len(robot.joints)
    if home:
        assert m.key_qpos.shape == (1, len(robot.joints))  # the keyframe lost the free joint's 7 numbers
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(d.xpos[m.body("pelvis").id], [0, 0, STAND_HEIGHT_M], atol=1e-9)
    np.testing.assert_allclose(_sole_bottoms_z(m, d), 0.0, atol=1e-9)


def test_it_stands_for_5_s_at_rest_neither_falling_nor_sinking(tmp_path):
    robot = load_robot_config(write_humanoid(tmp_path))
    backend = MujocoBackend(robot, count_contacts=True)
    heights, soles = [], []

    def watch(t_s: float, q: np.ndarray) -> None:
        m, d = backend.sim.model, backend.data
        heights.append(d.xpos[m.body("pelvis").id].copy())
        soles.append(_sole_bottoms_z(m, d))

    with ControlLoop(backend, 50.0, threaded=False, on_tick=watch) as loop:
        loop.run_for(5.0)
        legs = [robot.joint_names.index(n) for n in LEGS]
        q_legs = backend.read_positions()[legs]
    heights, soles = np.array(heights), np.array(soles)
    assert len(heights) >= 250
    np.testing.assert_allclose(heights, np.tile([0, 0, STAND_HEIGHT_M], (len(heights), 1)), atol=1e-9)
    assert np.abs(soles).max() < 2e-3  # on the floor, not in it nor above it
    assert np.abs(q_legs - robot.rest_q_rad[legs]).max() < 0.01  # the leg servos hold the stance
    # the hips do not collide with the pelvis they hang from (MuJoCo's parent exclusion ends at a world-welded body)
    assert backend.self_collision_s == 0.0
