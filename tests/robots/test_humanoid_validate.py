"""`robots validate` on a floating-base humanoid with held joints (the synthetic one of humanoid_fixture)."""

from __future__ import annotations

import pytest
import yaml

from robogest.tools.validate import validate
from tests.robots.humanoid_fixture import ARMS, LEGS, robot_yaml, write_humanoid


def test_the_synthetic_humanoid_is_valid(tmp_path):
    assert [str(p) for p in validate(write_humanoid(tmp_path))] == []


@pytest.mark.parametrize("held", [LEGS + ARMS["l"], [*LEGS, "waist_yaw"]], ids=["left_arm", "waist"])
def test_vectors_only_held_joints_point_are_not_asked_to_follow(tmp_path, held):
    """A held arm's (or, waist held, the shoulder line's) vectors cannot follow their bones: not a problem."""
    assert [str(p) for p in validate(write_humanoid(tmp_path, held=held))] == []


def test_a_vector_a_free_joint_points_is_still_checked(tmp_path):
    path = write_humanoid(tmp_path)
    raw = robot_yaml()
    raw["retarget"][2]["robot"] = raw["retarget"][2]["robot"][::-1]  # l_shoulder->l_elbow link reversed
    path.write_text(yaml.safe_dump(raw))
    (problem,) = [str(p) for p in validate(path)]
    assert "retarget[2]" in problem and "deg away" in problem


def _held_knee_at(tmp_path, rest_rad: float) -> str:
    """The one problem of the humanoid with its (held) left knee's rest_rad changed."""
    path = write_humanoid(tmp_path)
    raw = robot_yaml()
    next(j for j in raw["joints"] if j["name"] == "l_knee")["rest_rad"] = rest_rad
    path.write_text(yaml.safe_dump(raw))
    (problem,) = [str(p) for p in validate(path)]
    return problem


def test_a_held_joints_home_must_be_its_rest_too(tmp_path):
    problem = _held_knee_at(tmp_path, 0.2)
    assert 'joint "l_knee"' in problem and "rest_rad 0.2" in problem


def test_a_held_joint_at_rest_outside_its_limits_is_refused(tmp_path):
    problem = _held_knee_at(tmp_path, -0.1)  # held there, below the knee's lower limit 0
    assert "joints[2]" in problem and "rest_rad (-0.1) must lie within" in problem
