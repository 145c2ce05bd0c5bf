from __future__ import annotations

import itertools

import numpy as np
import pytest

from robogest.generators.poses import READY, REST, dofs_to_rotations, pose
from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL, Skeleton
from robogest.retarget import DirectionIK


def motion_from_dofs(dofs: np.ndarray, fps: float = 20.0) -> HumanMotion:
    rot = dofs_to_rotations(dofs)
    return HumanMotion(fps, rot, np.tile([0.0, 1.0, 0.0], (len(dofs), 1)))


def random_reachable_dofs(rng: np.random.Generator, n: int) -> np.ndarray:
    """Arm poses inside what a 4-DOF arm with these limits can reach, away from the straight-elbow singularity."""
    d = np.zeros((n, len(REST)))
    for side in ("l", "r"):
        p = {f"{side}_abd": rng.uniform(0.05, 1.2, n), f"{side}_flex": rng.uniform(-0.2, 1.0, n),
             f"{side}_twist": rng.uniform(-0.5, 0.8, n), f"{side}_elbow": rng.uniform(0.4, 1.6, n)}  # fmt: skip
        for k, v in p.items():
            d[:, list(pose(**{k: 1.0})).index(1.0)] = v
    return d


def test_reachable_motion_has_small_direction_error(make_robot, rng):
    ik = DirectionIK(make_robot(), iterations=30)
    # Smooth path through random poses so the warm start is meaningful.
    keys = random_reachable_dofs(rng, 6)
    dofs = np.concatenate([np.linspace(a, b, 15) for a, b in itertools.pairwise(keys)])
    res = ik.retarget(motion_from_dofs(dofs))
    assert res.q_rad.shape == (len(dofs), 9)
    assert np.degrees(res.direction_error_rad).max() < 2.0


def test_rest_and_ready_poses_match(make_robot):
    ik = DirectionIK(make_robot(), iterations=30)
    res = ik.retarget(motion_from_dofs(np.stack([REST, READY])))
    assert np.degrees(res.direction_error_rad).max() < 1.0


def test_limits_respected_for_unreachable_targets(make_robot, rng):
    robot = make_robot()
    ik = DirectionIK(robot)
    # Arms thrown behind the back and twisted far beyond the robot's range.
    d = np.zeros((20, len(REST)))
    d[:, list(pose(l_flex=1.0)).index(1.0)] = -2.5
    d[:, list(pose(r_twist=1.0)).index(1.0)] = 3.0
    d[:, list(pose(r_elbow=1.0)).index(1.0)] = -1.0
    res = ik.retarget(motion_from_dofs(d))
    assert (res.q_rad >= robot.q_min_rad - 1e-12).all() and (res.q_rad <= robot.q_max_rad + 1e-12).all()
    assert res.direction_error_rad.max() > 0.3  # it really was unreachable


def test_subset_mapping_single_arm(make_robot):
    robot = make_robot(sides=("r",))
    ik = DirectionIK(robot, iterations=30)
    res = ik.retarget(motion_from_dofs(np.stack([READY, REST])))
    assert res.q_rad.shape == (2, 5) and res.direction_error_rad.shape == (2, 2)
    assert np.degrees(res.direction_error_rad).max() < 1.0


def test_a_pose_skeleton_gives_same_angles_as_t_pose(make_robot, rng):
    """Rest pose is irrelevant: the same world motion on an A-pose skeleton retargets identically."""
    dofs = random_reachable_dofs(rng, 5)
    t_motion = motion_from_dofs(dofs)
    offs = CANONICAL.offsets_m.copy()
    names = CANONICAL.names
    corr = {}
    for side, sign in (("l", 1.0), ("r", -1.0)):
        d_t = np.array([sign, 0.0, 0.0])
        d_a = np.array([sign * np.cos(np.pi / 4), -np.sin(np.pi / 4), 0.0])  # arms 45° down
        c = R.between(d_a, d_t)  # rotation taking the A-pose bone onto the T-pose bone
        corr[side] = c
        for j in ("elbow", "wrist", "hand"):
            i = names.index(f"{side}_{j}")
            offs[i] = d_a * np.linalg.norm(offs[i])
    a_skel = Skeleton(names, CANONICAL.parents, offs)
    rot = t_motion.rotations.copy()
    for side, c in corr.items():
        sh, el, wr = (names.index(f"{side}_{j}") for j in ("shoulder", "elbow", "wrist"))
        rot[:, sh] = R.mul(rot[:, sh], c)
        rot[:, el] = R.mul(R.mul(R.conj(c), rot[:, el]), c)
        rot[:, wr] = R.mul(R.mul(R.conj(c), rot[:, wr]), c)
    a_motion = HumanMotion(t_motion.fps, rot, t_motion.root_pos_m, a_skel)
    np.testing.assert_allclose(a_motion.positions(), t_motion.positions(), atol=1e-9)
    ik = DirectionIK(make_robot())
    np.testing.assert_allclose(ik.retarget(a_motion).q_rad, ik.retarget(t_motion).q_rad, atol=1e-9)


@pytest.mark.parametrize("bad", ["nope_site"])
def test_unknown_site_is_a_config_error(make_robot, tmp_path, bad):
    import yaml

    from robogest.errors import ConfigError
    from robogest.robot.config import load_robot_config

    robot = make_robot()
    raw = yaml.safe_load(robot.path.read_text())
    raw["retarget"][0]["robot"][1] = bad
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"bad\.yaml: key retarget\[0\]\.robot: 'nope_site' is not a site"):
        DirectionIK(load_robot_config(p))
    raw["retarget"][0]["robot"][1] = "l_elbow_sit"  # a typo gets the name it is closest to, as validate gives it
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"'l_elbow_sit' is not a site in .*did you mean 'l_elbow_site'\?"):
        DirectionIK(load_robot_config(p))


def test_a_robot_without_a_file_is_named_in_a_missing_joint_error(make_robot):
    """A robot built in memory (no YAML file) is named by its name, not "None", when its joint is not in the MJCF."""
    import re

    from robogest.errors import ConfigError

    robot = make_robot()
    joints = [robot.joints[0].model_copy(update={"name": "nope_joint"}), *robot.joints[1:]]
    robot = robot.model_copy(update={"path": None, "model": str(robot.model_path), "joints": joints})
    expected = rf"^{re.escape(robot.name)}: key joints\[0\]\.name: 'nope_joint' is not a joint"
    with pytest.raises(ConfigError, match=expected):
        DirectionIK(robot)


def test_no_commanded_pose_penetrates_the_desk(rng):
    """The desk arm must never be told to push its hand into the desk, whatever the human does."""
    from robogest.robot import find_robot

    robot = find_robot("desk_arm_sts3215")
    d = np.tile(REST, (120, 1))
    for k, v in {"r_abd": rng.uniform(0, 1.5, 120), "r_flex": rng.uniform(-0.5, 2.0, 120),
                 "r_twist": rng.uniform(-1, 1, 120), "r_elbow": rng.uniform(0, 2.0, 120)}.items():  # fmt: skip
        d[:, list(pose(**{k: 1.0})).index(1.0)] = v
    motion = motion_from_dofs(d)
    free = DirectionIK(robot, avoid_collisions=False)
    raw = free.retarget(motion).q_rad
    assert sum(free.in_collision(q) for q in raw) > 3  # these motions really do reach into the desk
    ik = DirectionIK(robot)
    res = ik.retarget(motion)
    assert not any(ik.in_collision(q) for q in res.q_rad)
    assert res.collision_frames.sum() > 3


def test_held_joints_stay_at_rest_and_the_others_still_follow(make_robot, rng):
    """Held joints are no IK variables: exactly at rest in every frame (even warm-started elsewhere), while the
    free joints still point the links whose chains run through them."""
    robot = make_robot()
    held_names = {"torso_yaw", "l_elbow"}
    joints = [j.model_copy(update={"held": j.name in held_names}) for j in robot.joints]
    robot = robot.model_copy(update={"joints": joints})
    held = robot.held_mask
    keys = random_reachable_dofs(rng, 5)
    dofs = np.concatenate([np.linspace(a, b, 12) for a, b in itertools.pairwise(keys)])
    q0 = np.clip(robot.rest_q_rad + 0.4, robot.q_min_rad, robot.q_max_rad)
    res = DirectionIK(robot, iterations=20).retarget(motion_from_dofs(dofs), q0=q0)
    assert np.array_equal(res.q_rad[:, held], np.broadcast_to(robot.rest_q_rad[held], res.q_rad[:, held].shape))
    assert np.ptp(res.q_rad[:, ~held], axis=0).min() > 0.05  # every free joint gestures
    right_arm = [k for k, v in enumerate(robot.retarget) if v.robot[1] in ("r_elbow_site", "r_wrist_site")]
    assert np.degrees(res.direction_error_rad[:, right_arm]).max() < 5.0  # nothing held on that chain
