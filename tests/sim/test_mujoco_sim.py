"""MuJoCo backend: models step stably, servos behave like servos, simulate() tracks, renders and muxes audio."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from robogest.backends.base import get_backend_factory
from robogest.backends.mujoco_sim import MujocoBackend, load_sim_model, simulate, sine_test_trajectory
from robogest.errors import InputError, MissingDependencyError, SafetyError
from robogest.robot.registry import find_robot, list_robots

ROBOTS = sorted(list_robots())


@pytest.mark.parametrize("name", ROBOTS)
def test_model_holds_home_with_home_ctrl(name):
    robot = find_robot(name)
    sim = load_sim_model(robot)
    d = mujoco.MjData(sim.model)
    mujoco.mj_resetDataKeyframe(sim.model, d, mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_KEY, "home"))
    for _ in range(int(2.0 / sim.model.opt.timestep)):
        mujoco.mj_step(sim.model, d)
    assert np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))
    err = np.degrees(np.abs(d.qpos[sim.qpos_idx] - robot.rest_q_rad))
    assert err.max() < 1.0, dict(zip(robot.joint_names, err.round(2), strict=False))
    assert np.abs(d.qvel).max() < 0.01


def test_registered_as_sim():
    robot = find_robot("humanoid_xl430")
    backend = get_backend_factory("sim")(robot, port="/dev/null")
    assert isinstance(backend, MujocoBackend) and backend.realtime is False


def step_toward(b: MujocoBackend, goal: np.ndarray, ticks: int) -> None:
    """``ticks`` guarded goals, each a step toward ``goal`` at 90 % of the velocity limit, one per control period."""
    lim = 0.9 * b.robot.v_max_rad_s * b.control_period_s
    for _ in range(ticks):
        last = b.last_goal_rad if b.last_goal_rad is not None else b.read_positions()
        b.write_goal(last + np.clip(goal - last, -lim, lim))
        b.advance(b.control_period_s)


def test_backend_moves_to_goal_and_keeps_time():
    robot = find_robot("humanoid_xl430")
    with MujocoBackend(robot) as b:
        b.set_control_rate(100.0)
        np.testing.assert_allclose(b.read_positions(), robot.rest_q_rad, atol=1e-9)
        goal = robot.rest_q_rad.copy()
        goal[robot.joint_names.index("l_shoulder_pitch")] = 1.0
        goal[robot.joint_names.index("head_pan")] = -0.5
        step_toward(b, goal, 100)  # 1 s in 10 ms steps: no drift
        assert b.time_s == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(b.read_positions(), goal, atol=np.radians(2.0))
        log = b.log
        assert log["q_rad"].shape == (101, 11) and log["t_s"][0] == 0 and log["t_s"][-1] == pytest.approx(1.0)
        # the guard: outside the limits, NaN, or a step beyond the velocity limit is refused and nothing is sent
        sent = b.data.ctrl[b.sim.act_idx].copy()
        with pytest.raises(
            SafetyError, match=r"torso_yaw = 2\.2000 rad outside \[-1\.2000, 1\.2000\] rad.*and 8 more joints"
        ):
            b.write_goal(robot.q_max_rad + 1.0)
        with pytest.raises(SafetyError, match="torso_yaw = nan is not finite"):
            b.write_goal(np.full(11, np.nan))
        jump = goal.copy()
        jump[robot.joint_names.index("head_pan")] = 0.5
        with pytest.raises(SafetyError, match=r"head_pan steps 1\.0000 rad in one 10\.0 ms tick, limit 0\.0420 rad"):
            b.write_goal(jump)
        with pytest.raises(InputError):
            b.write_goal(np.zeros(3))
        np.testing.assert_array_equal(b.data.ctrl[b.sim.act_idx], sent)
        np.testing.assert_array_equal(b.last_goal_rad, sent)
    # leaving the block glided to rest and disconnected; disconnect twice is safe
    b.disconnect()
    assert b.sim is None


def test_torque_off_lets_the_arm_fall():
    robot = find_robot("humanoid_sts3215")
    i = robot.joint_names.index("r_shoulder_pitch")
    b = MujocoBackend(robot)
    b.connect()
    goal = robot.rest_q_rad.copy()
    goal[i] = 1.5  # arm raised forward, past horizontal
    step_toward(b, goal, 75)  # 1.5 s
    held = b.read_positions()[i]
    assert held == pytest.approx(1.5, abs=0.05)
    b.set_torque(False)
    b.advance(1.0)
    # unpowered, the gearbox (damping + friction) lets it sag slowly rather than drop
    assert b.read_positions()[i] < held - 0.1
    b.disconnect()


def test_saturated_servo_runs_at_no_load_speed():
    """A big step: speed is capped near the datasheet no-load speed (back-EMF damping + stall torque)."""
    robot = find_robot("humanoid_xl430")
    i = robot.joint_names.index("head_pan")
    with MujocoBackend(robot) as b:
        goal = robot.rest_q_rad.copy()
        goal[i] = 1.4
        b._send_goal(goal)  # past the guard on purpose: a step it would refuse, to see the motor model saturate
        peak = 0.0
        for _ in range(150):
            b.advance(0.002)
            peak = max(peak, abs(b.read_velocities()[i]))
    assert 0.6 * 6.39 < peak < 1.05 * 6.39  # XL430-W250 no-load 61 rpm at 12 V


@pytest.mark.parametrize("name", ROBOTS)
def test_simulate_tracks_sine(name):
    robot = find_robot(name)
    traj = sine_test_trajectory(robot, duration_s=3.0)
    rep = simulate(traj, robot)
    assert rep.q_achieved_rad.shape == traj.q_rad.shape
    assert rep.tracking_rms_deg.shape == (len(robot.joints),)
    # servo lag is real but small; a broken mapping (wrong joint, wrong sign) gives tens of degrees
    assert 0.05 < rep.tracking_rms_deg_overall < 3.0
    assert rep.tracking_rms_deg.max() < 4.0
    assert rep.max_abs_error_deg < 8.0
    assert rep.self_collision_s == 0.0
    np.testing.assert_allclose(rep.q_achieved_rad[0], traj.q_rad[0], atol=1e-9)


def test_simulate_reorders_and_validates_joints():
    robot = find_robot("desk_arm_sts3215")
    traj = sine_test_trajectory(robot, duration_s=1.0)
    rev = dataclasses.replace(traj, q_rad=traj.q_rad[:, ::-1].copy(), joint_names=traj.joint_names[::-1])
    a, b = simulate(traj, robot), simulate(rev, robot)
    np.testing.assert_allclose(a.q_achieved_rad, b.q_achieved_rad)
    other = find_robot("humanoid_xl430")
    with pytest.raises(InputError, match="do not match robot"):
        simulate(traj, other)
    bad = dataclasses.replace(traj, q_rad=np.where(traj.t_s[:, None] > 0.5, np.nan, traj.q_rad))
    with pytest.raises(SafetyError):
        simulate(bad, robot)


def test_view_without_display_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    robot = find_robot("desk_arm_sts3215")
    with pytest.raises(MissingDependencyError, match="display"):
        simulate(sine_test_trajectory(robot, duration_s=0.2), robot, view=True)


def test_progress_reports_to_the_end():
    robot = find_robot("desk_arm_sts3215")
    calls = []
    simulate(sine_test_trajectory(robot, duration_s=0.5), robot, progress=lambda d, t: calls.append((d, t)))
    assert calls[-1][0] == calls[-1][1] == pytest.approx(0.5) and len(calls) > 10  # (trajectory s, duration s)
