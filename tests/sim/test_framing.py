"""A scene without a named camera (an imported humanoid's MJCF) is filmed by a camera that faces the robot's front
and frames its upper body at any frame size; scenes with their own cameras keep them."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robogest.backends.mujoco_sim import load_sim_model
from robogest.backends.render import make_renderer, video_camera
from robogest.errors import MissingDependencyError
from robogest.robot.config import load_robot_config
from robogest.robot.registry import find_robot
from tests.robots.humanoid_fixture import write_humanoid

UPPER_BODY = ("head", "torso", "l_upper_arm", "r_upper_arm", "l_hand", "r_hand")


def _segmentation(robot, width: int, height: int) -> tuple[mujoco.MjModel, np.ndarray]:
    """``(model, (H, W) body id per pixel, -1 for none)`` of the robot at rest through its video camera."""
    sim = load_sim_model(robot)
    m = sim.model
    d = mujoco.MjData(m)
    d.qpos[sim.qpos_idx] = robot.rest_q_rad
    mujoco.mj_forward(m, d)
    try:
        renderer = make_renderer(m, width, height)
    except MissingDependencyError as e:
        pytest.skip(f"no offscreen GL here: {e}")
    try:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(d, camera=video_camera(m, d, robot, width, height))
        seg = renderer.render()
    finally:
        renderer.close()
    geom = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
    return m, np.where(geom >= 0, m.geom_bodyid[np.maximum(geom, 0)], -1)


@pytest.mark.parametrize("size", [(160, 120), (320, 96), (96, 200)], ids=["4:3", "wide", "tall"])
def test_the_upper_body_is_in_frame_facing_the_camera(tmp_path, size):
    robot = load_robot_config(write_humanoid(tmp_path))
    m, body = _segmentation(robot, *size)
    border = np.concatenate([body[0], body[-1], body[:, 0], body[:, -1]])
    for name in UPPER_BODY:
        b = m.body(name).id
        assert (body == b).sum() >= 4, f"{name} is not in the frame"
        if name != "torso":  # the torso runs into the pelvis below the frame's bottom edge at most
            assert b not in border, f"{name} is cut by the frame's edge"
    cols = {s: np.nonzero(body == m.body(f"{s}_hand").id)[1].mean() for s in ("l", "r")}
    assert cols["l"] > cols["r"]  # facing the robot: its left hand is on the image's right


def test_shipped_scenes_keep_their_own_camera():
    robot = find_robot("humanoid_xl430")
    m = load_sim_model(robot).model
    d = mujoco.MjData(m)
    assert video_camera(m, d, robot, 320, 240) == mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "three_quarter")
