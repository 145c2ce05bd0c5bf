"""Held joints (a humanoid's legs, ``held: true``) never leave their rest angle: not in the batch safety layer, not
in the online limiter, not in what the control loop sends a backend, and the backend's goal guard refuses a goal
that would move one off it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robogest.backends.base import Backend, check_goal
from robogest.backends.control import ControlLoop
from robogest.backends.rest import go_to_rest
from robogest.errors import SafetyError
from robogest.robot import find_robot
from robogest.robot.config import RobotConfig
from robogest.safety import JointLimits, SafetyConfig, apply_safety
from robogest.safety.online import OnlineLimiter
from robogest.trajectory import Trajectory
from tests.safety.test_safety_properties import cases


def with_held(robot: RobotConfig, names: list[str]) -> RobotConfig:
    """``robot`` with the named joints held (rest angles as in the YAML)."""
    joints = [j.model_copy(update={"held": j.name in names}) for j in robot.joints]
    return robot.model_copy(update={"joints": joints})


class RecordingBackend(Backend):
    """A backend that only records the goals that passed its guard; the robot sits wherever it is told."""

    realtime = False

    def __init__(self, robot: RobotConfig, q0_rad: np.ndarray) -> None:
        super().__init__(robot)
        self.q = np.asarray(q0_rad, float).copy()
        self.sent: list[np.ndarray] = []
        self.is_connected = False

    def connect(self) -> None:
        self.is_connected = True
        self._connected()

    def read_positions(self) -> np.ndarray:
        return self.q.copy()

    def set_torque(self, on: bool) -> None:
        pass

    def _send_goal(self, q_rad: np.ndarray) -> None:
        self.sent.append(q_rad.copy())
        self.q = q_rad.copy()

    def disconnect(self) -> None:
        self.is_connected = False


HELD = ["torso_yaw", "l_elbow", "r_shoulder_roll"]  # rest 0.0, 0.3 (inside), 0.1 (near the lower limit -0.1)


@pytest.fixture(scope="module")
def robot() -> RobotConfig:
    return with_held(find_robot("humanoid_xl430"), HELD)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=cases(), held_bits=st.integers(1, 2**12 - 1))
def test_batch_safety_pins_held_joints_exactly(case, held_bits):
    lim: JointLimits = case["limits"]
    held = np.array([(held_bits >> j) & 1 for j in range(lim.n_joints)], bool)
    limits = JointLimits(lim.q_min_rad, lim.q_max_rad, lim.v_max_rad_s, lim.a_max_rad_s2, lim.rest_q_rad,
                         held_mask=held)  # fmt: skip
    q0 = case["q0"]
    if q0 is not None:
        q0 = np.where(held, lim.rest_q_rad, q0)  # a held joint starts at its angle
    res = apply_safety(case["q"], limits, case["fps"], case["silent"], q0, case["config"])
    assert np.array_equal(res.q_rad[:, held], np.broadcast_to(lim.rest_q_rad[held], res.q_rad[:, held].shape))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["noise", "far", "nan_free_steps"]))
def test_whatever_trajectory_goes_in_held_joints_never_leave_rest_at_the_backend(robot, seed, kind):
    """Any trajectory (even one that moves held joints, as a file made for the robot before they were held), played
    through the control loop and its close: every goal the backend accepted has the held joints at rest."""
    rng = np.random.default_rng(seed)
    n = 60
    lo, hi = robot.q_min_rad, robot.q_max_rad
    if kind == "noise":
        q = rng.uniform(lo, hi, (n, len(lo)))
    elif kind == "far":
        q = np.where(rng.random((n, len(lo))) < 0.5, lo, hi)
    else:
        q = np.repeat(rng.uniform(lo, hi, (4, len(lo))), n // 4, axis=0)
    t = np.arange(len(q)) / 50.0
    traj = Trajectory(t_s=t, q_rad=q, joint_names=robot.joint_names, q_min_rad=lo, q_max_rad=hi,
                      v_max_rad_s=robot.v_max_rad_s, a_max_rad_s2=robot.a_max_rad_s2, rest_q_rad=robot.rest_q_rad,
                      silent=np.zeros(len(q), bool))  # fmt: skip
    backend = RecordingBackend(robot, robot.rest_q_rad)
    held = robot.held_mask
    with ControlLoop(backend, 50.0, threaded=False) as loop:
        loop.play(traj).wait(timeout_s=30)
        loop.set_idle(lambda t_s: rng.uniform(lo, hi))  # an idle source that ignores held joints too
        loop.run_for(0.3)
    sent = np.array(backend.sent)
    assert len(sent) > 10
    assert np.array_equal(sent[:, held], np.broadcast_to(robot.rest_q_rad[held], sent[:, held].shape))


def test_a_held_joint_found_off_its_angle_glides_onto_it_and_stays(robot):
    """At connect a held joint that sags elsewhere is only ever brought closer to its angle, then held there."""
    q0 = robot.rest_q_rad.copy()
    k = robot.joint_names.index("l_elbow")
    q0[k] = 1.2  # rest 0.3
    backend = RecordingBackend(robot, q0)
    with ControlLoop(backend, 50.0, threaded=False) as loop:
        loop.run_for(2.0)
    d = np.abs(np.array(backend.sent)[:, k] - 0.3)
    assert np.all(np.diff(d) <= 1e-12) and d[-1] == 0.0
    assert go_to_rest(backend) is None


class NoisyBackend(RecordingBackend):
    """Readings flicker by a tick or two around the pose, as real encoders do."""

    def read_positions(self) -> np.ndarray:
        self.reads = getattr(self, "reads", 0) + 1
        return self.q + (0.002 if self.reads % 2 else -0.002)


def test_a_noisy_reading_of_a_held_joint_at_start_is_not_refused(robot):
    """The start goal holds the present pose, but the guard reads the pose again for its reference: a held joint's
    goal taken from the first reading could lie farther from its angle than the second one (refused)."""
    backend = NoisyBackend(robot, robot.rest_q_rad)
    with ControlLoop(backend, 50.0, threaded=False) as loop:
        loop.run_for(0.2)
    sent = np.array(backend.sent)
    assert np.array_equal(sent[:, robot.held_mask], np.broadcast_to(robot.rest_q_rad[robot.held_mask],
                                                                     sent[:, robot.held_mask].shape))  # fmt: skip


def test_goal_guard_refuses_a_goal_that_moves_a_held_joint(robot):
    rest = robot.rest_q_rad
    k = robot.joint_names.index("l_elbow")
    period = 0.02
    np.testing.assert_array_equal(check_goal(rest, robot, rest, period), rest)
    nudged = rest.copy()
    nudged[k] += 0.01  # inside the limits and the velocity limit: only being held forbids it
    with pytest.raises(SafetyError, match=r"l_elbow = 0\.3100 rad moves a held joint off its angle 0\.3000 rad"):
        check_goal(nudged, robot, rest, period)
    away = rest.copy()
    away[k] = 0.5
    closer = away.copy()
    closer[k] = 0.45
    check_goal(closer, robot, away, period)  # towards its angle from where it is: allowed
    with pytest.raises(SafetyError, match="held joint"):
        check_goal(away + np.where(np.arange(len(rest)) == k, 0.01, 0.0), robot, away, period)
    with pytest.raises(SafetyError, match="held joint"):  # past its angle is off it too
        check_goal(np.where(np.arange(len(rest)) == k, 0.29, rest), robot, np.where(np.arange(len(rest)) == k, 0.31,
                   rest), period)  # fmt: skip


def test_write_goal_refuses_for_every_backend_and_sends_nothing(robot):
    backend = RecordingBackend(robot, robot.rest_q_rad)
    backend.connect()
    backend.write_goal(robot.rest_q_rad)
    bad = robot.rest_q_rad + np.where(robot.held_mask, 0.005, 0.0)
    with pytest.raises(SafetyError, match=r"torso_yaw = 0\.0050 rad moves a held joint"):
        backend.write_goal(bad, source="test")
    assert len(backend.sent) == 1


def test_online_limiter_pins_held_joints(robot):
    lim = OnlineLimiter.for_robot(robot, 0.01, robot.rest_q_rad)
    rng = np.random.default_rng(0)
    for _ in range(200):
        q = lim.step(rng.uniform(robot.q_min_rad, robot.q_max_rad))
        assert np.array_equal(q[robot.held_mask], robot.rest_q_rad[robot.held_mask])


def test_safety_config_margin_does_not_pull_a_held_joint_off_a_rest_near_its_limit(robot):
    """r_shoulder_roll rests at 0.1, within the 0.2 margin of its lower limit -0.1: held, it stays at 0.1."""
    limits = JointLimits.from_robot(robot)
    q = np.tile(robot.rest_q_rad, (50, 1))
    res = apply_safety(q, limits, 50.0, config=SafetyConfig(margin_rad=0.25))
    k = robot.joint_names.index("r_shoulder_roll")
    assert np.all(res.q_rad[:, k] == 0.1)
