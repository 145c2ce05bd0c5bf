"""The goal guard at the last step before the hardware: every backend refuses any goal that is not finite, outside
the joint limits or faster than the velocity limit from the last goal sent, writes nothing for it, and the run
ends at rest with torque off. Checked on what really arrived: the simulated servos' goal writes, the MuJoCo log."""

from __future__ import annotations

import dataclasses
import re
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import Backend, check_goal, get_backend_factory
from robogest.backends.mujoco_sim import MujocoBackend, sine_test_trajectory
from robogest.backends.player import play
from robogest.cli.main import main
from robogest.errors import ConfigError, InputError, SafetyError
from robogest.robot import find_robot
from robogest.trajectory import Trajectory, check_matches
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.conftest import move_by_hand, sine_traj

RATE_HZ = 50.0
KINDS = ["ok", "ok", "ok", "ok", "nan", "inf", "out", "fast"]  # mostly legal goals, some of each illegal kind


class GoalLog:
    """Every goal-position write each simulated servo received, decoded as sent (before the servo's own clamp)."""

    def __init__(self, bus: VirtualBus) -> None:
        self.ticks: dict[int, list[int]] = {s.id: [] for s in bus.servos}
        for s in bus.servos:
            reg = s.spec.reg("goal")

            def write(addr: int, data: bytes, s=s, reg=reg, orig=s.write) -> int:
                if addr <= reg.addr and reg.addr + reg.size <= addr + len(data):
                    off = reg.addr - addr
                    self.ticks[s.id].append(s._decode(reg, bytes(data[off : off + reg.size])))
                return orig(addr, data)

            s.write = write

    def rad(self, backend) -> np.ndarray:
        """``(N, J)`` radians, joint order."""
        cols = [self.ticks[int(i)] for i in backend.ids]
        assert len({len(c) for c in cols}) == 1, "every sync write reaches every servo"
        return backend.ticks_to_rad(np.array(cols, dtype=np.int64).T.reshape(-1, len(cols)))


def make_goal(
    kind: str, j: int, x: float, frac: list[float], last: np.ndarray, robot, rate_hz: float = RATE_HZ
) -> np.ndarray:
    """A goal of the given kind after ``last``: legal ones move each joint by ``frac`` of its per-tick limit."""
    lo, hi, step = robot.q_min_rad, robot.q_max_rad, robot.v_max_rad_s / rate_hz
    q = np.clip(last + np.asarray(frac) * step, lo, hi)
    if kind == "nan":
        q[j] = np.nan
    elif kind == "inf":
        q[j] = np.inf if x > 0.5 else -np.inf
    elif kind == "out":
        q[j] = hi[j] + 1e-6 + x if x > 0.5 else lo[j] - 1e-6 - x
    elif kind == "fast":
        q[j] = last[j] + (1.5 + 18 * x) * step[j] * (1 if last[j] < 0.5 * (lo[j] + hi[j]) else -1)
    return q


def steps_strategy(n_joints: int):
    one = st.tuples(
        st.sampled_from(KINDS),
        st.integers(0, n_joints - 1),
        st.floats(0, 1),
        st.lists(st.floats(-0.95, 0.95), min_size=n_joints, max_size=n_joints),
    )
    return st.lists(one, min_size=1, max_size=8)


def drive(backend: Backend, steps, advance, rate_hz: float = RATE_HZ) -> tuple[np.ndarray, SafetyError | None]:
    """Connect, hold the present pose, torque on, send ``steps`` until one is refused; always shut down."""
    robot = backend.robot
    backend.set_control_rate(rate_hz)
    backend.connect()
    start = backend.read_positions()
    refused = None
    try:
        backend.write_goal(start)
        backend.set_torque(True)
        last = start
        for kind, j, x, frac in steps:
            q = make_goal(kind, j, x, frac, last, robot, rate_hz)
            try:
                backend.write_goal(q)
            except SafetyError as e:
                refused = e
                break
            assert kind == "ok", f"an illegal goal ({kind}) was accepted"
            np.testing.assert_array_equal(backend.last_goal_rad, q)
            last = q
            advance()
    finally:
        backend.shutdown()
    first_bad = next((s for s in steps if s[0] != "ok"), None)
    assert (refused is None) == (first_bad is None), f"legal goals must pass, the first illegal one must raise: {steps}"
    if refused is not None:
        msg = str(refused)
        assert "\n" not in msg and robot.joint_names[first_bad[1]] in msg and "nothing was sent" in msg
    return start, refused


def assert_safe_goal_sequence(
    goals: np.ndarray, start: np.ndarray, robot, tol_rad: float, rate_hz: float = RATE_HZ
) -> None:
    """Every goal finite, in limits, within the per-tick velocity bound from the previous one (from ``start``)."""
    assert np.all(np.isfinite(goals))
    assert np.all(goals >= robot.q_min_rad - tol_rad) and np.all(goals <= robot.q_max_rad + tol_rad)
    steps = np.abs(np.diff(np.vstack([start, goals]), axis=0))
    assert np.all(steps <= robot.v_max_rad_s / rate_hz + tol_rad), steps.max(axis=0)


# --- the guard itself ---------------------------------------------------------------------------------------------
def test_check_goal_names_joint_value_limit_and_source():
    robot = find_robot("humanoid_xl430")
    rest, period = robot.rest_q_rad, 0.02
    np.testing.assert_array_equal(check_goal(rest, robot, rest, period), rest)
    j = robot.joint_names.index("l_elbow")
    edge = rest.copy()
    edge[j] += robot.v_max_rad_s[j] * period  # exactly the velocity limit: allowed
    check_goal(edge, robot, rest, period)
    fast = rest.copy()
    fast[j] += 1.01 * robot.v_max_rad_s[j] * period
    with pytest.raises(
        SafetyError, match=r"l_elbow steps 0\.\d+ rad in one 20\.0 ms tick, limit 0\.\d+ rad .*source: demo"
    ):
        check_goal(fast, robot, rest, period, source="demo")
    low = rest.copy()
    low[j] = robot.q_min_rad[j] - 1e-6
    with pytest.raises(SafetyError, match=r"l_elbow = -?\d\.\d+ rad outside \[-?\d\.\d+, -?\d\.\d+\] rad"):
        check_goal(low, robot, low, period)  # outside the limits even without moving
    with pytest.raises(SafetyError, match=r"l_elbow = nan is not finite"):
        check_goal(np.where(np.arange(11) == j, np.nan, rest), robot, rest, period)
    with pytest.raises(InputError, match=r"shape \(3,\); expected \(11,\)"):
        check_goal(np.zeros(3), robot, rest, period)


def test_check_matches_refuses_a_file_that_disagrees_with_the_robot():
    robot = find_robot("humanoid_xl430")
    traj = sine_test_trajectory(robot, duration_s=0.5)
    check_matches(traj, robot)
    v = traj.v_max_rad_s.copy()
    v[2] = 1e9
    with pytest.raises(
        InputError, match=r"t\.npz: key v_max_rad_s of joint head_tilt is 1000000000\.0 but .*regenerate"
    ):
        check_matches(dataclasses.replace(traj, v_max_rad_s=v), robot, "t.npz")
    lo = traj.q_min_rad.copy()
    lo[0] = np.nan
    with pytest.raises(InputError, match=r"key q_min_rad of joint torso_yaw is nan"):
        check_matches(dataclasses.replace(traj, q_min_rad=lo), robot)
    q = traj.q_rad.copy()
    q[5:9, 4] = np.nan
    with pytest.raises(InputError, match=r"q_rad\[5\] of joint l_shoulder_roll is nan, not a finite angle \(4 such"):
        check_matches(dataclasses.replace(traj, q_rad=q), robot)
    with pytest.raises(InputError, match=r"pass the --robot it was made for \(humanoid_xl430\)"):
        check_matches(traj, find_robot("desk_arm_sts3215"))


# --- property tests: random goal sequences through the Python API -------------------------------------------------
SIM_ROBOT = find_robot("humanoid_xl430")


@settings(max_examples=25, deadline=None)
@given(steps=steps_strategy(len(SIM_ROBOT.joints)), rate_hz=st.sampled_from([20.0, 50.0, 200.0]))
@example(steps=[("ok", 0, 0.0, [0.0] * 9 + [0.875, 0.0])], rate_hz=200.0)  # a glide from a moving goal stream
def test_sim_backend_sends_only_safe_goals(steps, rate_hz):
    """At any control rate: the guard's bound and the shutdown ramp both follow it."""
    b = MujocoBackend(SIM_ROBOT)
    start, _ = drive(b, steps, lambda: b.advance(1.0 / rate_hz), rate_hz)
    goals = b.log["goal_rad"]
    assert_safe_goal_sequence(goals, start, SIM_ROBOT, tol_rad=1e-9, rate_hz=rate_hz)
    np.testing.assert_allclose(goals[-1], SIM_ROBOT.rest_q_rad, atol=1e-12)  # ended at rest
    assert b._torque is False and b.sim is None  # torque off, disconnected


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 2.0), ("feetech", 0.0)])
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(steps=steps_strategy(3))
def test_servo_backends_send_only_safe_goals_on_the_bus(tmp_path, family, protocol, steps):
    robot = make_robot(tmp_path / family, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        log = GoalLog(bus)
        backend = get_backend_factory(family)(robot, port=bus.port, health_hz=0)
        start, _ = drive(backend, steps, lambda: None)
        goals = log.rad(backend)
        tick = 1.0 / backend._tpr.min()  # one tick, radians
        assert_safe_goal_sequence(goals, start, robot, tol_rad=1.01 * tick)
        np.testing.assert_allclose(goals[-1], robot.rest_q_rad, atol=tick)  # ended at rest ...
        assert not any(s.torque_on for s in bus.servos)  # ... with torque off
        assert backend.torque_off_attempted and not backend.is_connected


# --- through the player and the CLI -------------------------------------------------------------------------------
def test_play_refuses_a_trajectory_whose_limits_are_not_the_robots(tmp_path):
    robot = make_robot(tmp_path)
    traj = sine_traj(robot)
    a = traj.a_max_rad_s2.copy()
    a[1] *= 2
    with VirtualBus(robot) as bus:
        log = GoalLog(bus)
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, health_hz=0)
        with pytest.raises(InputError, match=r"key a_max_rad_s2 of joint j1 is 80\.0 but 40\.0 in robot testbot"):
            play(dataclasses.replace(traj, a_max_rad_s2=a), backend, time_scale=4.0)
        assert all(len(v) == 0 for v in log.ticks.values()) and not any(s.torque_on for s in bus.servos)


def test_real_servos_refuse_a_robot_file_whose_limits_they_cannot_keep(tmp_path):
    """``robots validate`` refused a velocity limit past the servo's rating (or joint limits past the model's
    range), yet play, jog and the live session moved real servos with it. The control loop now refuses it before
    torque goes on: one line naming file and key, and nothing written to the bus."""
    fast = make_robot(tmp_path, v_max=6.0)  # the XL430 turns at 6.39 rad/s unloaded; 75 % of that is the most
    with VirtualBus(fast) as bus:
        log = GoalLog(bus)
        backend = get_backend_factory("dynamixel")(fast, port=bus.port, health_hz=0)
        with pytest.raises(
            ConfigError,
            match=r"testbot\.yaml: not safe to move real servos with \(nothing moved\): "
            r"key joints\[0\]\.max_velocity_rad_s: 6\.0 rad/s is more than 75%",
        ):
            play(sine_traj(fast), backend, time_scale=4.0)
        assert all(len(v) == 0 for v in log.ticks.values()) and not any(s.torque_on for s in bus.servos)


def test_a_goal_refused_mid_play_stops_at_rest_with_torque_off(tmp_path, monkeypatch):
    """A NaN that appears while playing (a stream, a bug) never reaches the bus: SafetyError, ramp to rest from the
    last goal sent, torque off."""
    robot = make_robot(tmp_path)
    traj = sine_traj(robot)
    original = traj.sample
    monkeypatch.setattr(traj, "sample", lambda t: original(t) * (np.nan if t >= 1.0 else 1.0))
    with VirtualBus(robot) as bus:
        log = GoalLog(bus)
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, health_hz=0)
        start = backend.ticks_to_rad(np.array([bus.servo(int(i)).get("present") for i in backend.ids]))
        with pytest.raises(SafetyError, match=r"j0 = nan is not finite.*source: trajectory playback") as ei:
            play(traj, backend, time_scale=4.0)
        goals = log.rad(backend)
        tick = 1.0 / backend._tpr.min()
        assert_safe_goal_sequence(goals, start, robot, tol_rad=1.01 * tick)
        np.testing.assert_allclose(goals[-1], robot.rest_q_rad, atol=tick)
        assert not any(s.torque_on for s in bus.servos) and not ei.value.report.completed


def _bad_files(tmp_path, robot) -> dict[str, tuple[object, str]]:
    traj = sine_test_trajectory(robot, duration_s=1.0)
    q = traj.q_rad.copy()
    q[10:14, robot.joint_names.index("r_elbow")] = np.nan  # the issue's four NaN samples in one joint
    files = {
        "nan-samples": (dataclasses.replace(traj, q_rad=q), r"q_rad\[10\] of joint r_elbow is nan"),
        "nan-lower-limits": (
            dataclasses.replace(traj, q_min_rad=np.full(11, np.nan)),
            r"key q_min_rad of joint torso_yaw is nan",
        ),
        "fast-limits": (
            dataclasses.replace(traj, v_max_rad_s=np.full(11, 1e9)),
            r"key v_max_rad_s of joint torso_yaw is 1000000000\.0",
        ),
    }
    out = {}
    for name, (t, pattern) in files.items():
        path = tmp_path / f"{name}.npz"
        Trajectory.save(t, path)
        out[name] = (path, pattern)
    return out


def test_cli_play_refuses_the_issues_files_before_anything_moves(tmp_path, capsys):
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot) as bus:
        log = GoalLog(bus)
        for name, (path, pattern) in _bad_files(tmp_path, robot).items():
            rc = main(["play", str(path), "--backend", "dynamixel", "--port", bus.port])
            err = capsys.readouterr().err.strip().splitlines()
            assert rc == 2 and len(err) == 1, (name, rc, err)
            assert str(path) in err[0] and re.search(pattern, err[0]), (name, err[0])
        time.sleep(0.05)
        rec = bus.record()
        assert all(len(v) == 0 for v in log.ticks.values())  # not one goal written
        assert not rec["torque_on"].any() and not any(s.torque_on for s in bus.servos)


def test_cli_play_goal_refused_mid_play_is_one_line_exit_4_at_rest(monkeypatch, capsys, tmp_path):
    robot = find_robot("humanoid_xl430")
    path = tmp_path / "ok.npz"
    sine_test_trajectory(robot, duration_s=2.0).save(path)
    sample = Trajectory.sample

    def nan_after_half_second(self, t_s):
        q = sample(self, t_s)
        return q * np.nan if t_s >= 0.5 else q

    monkeypatch.setattr(Trajectory, "sample", nan_after_half_second)
    with VirtualBus(robot) as bus:
        log = GoalLog(bus)
        rc = main(["play", str(path), "--backend", "dynamixel", "--port", bus.port])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 4 and len(err) == 1 and "unsafe goal for humanoid_xl430 refused" in err[0], err
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, health_hz=0)
        goals = log.rad(backend)
        tick = 1.0 / backend._tpr.min()
        assert np.all(goals >= robot.q_min_rad - tick) and np.all(goals <= robot.q_max_rad + tick)
        np.testing.assert_allclose(goals[-1], robot.rest_q_rad, atol=tick)
        assert not any(s.torque_on for s in bus.servos)


# --- servo write --------------------------------------------------------------------------------------------------
def test_servo_write_goal_position_checks_the_robots_limits(tmp_path, monkeypatch, capsys):
    robot = make_robot(tmp_path, name="wbot")
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    with VirtualBus(robot) as bus:
        be = get_backend_factory("dynamixel")(robot, port=bus.port)
        lo, hi = sorted((int(be.rad_to_ticks(robot.q_min_rad)[1]), int(be.rad_to_ticks(robot.q_max_rad)[1])))
        before = bus.servo(2).get("goal")
        base = ["servo", "write", "--port", bus.port, "--id", "2", "--robot", "wbot"]
        for where in (["--register", "goal_position"], ["--addr", "116", "--size", "4"]):
            for value in (hi + 1, lo - 1):
                assert main([*base, *where, "--value", str(value)]) == 4
                err = capsys.readouterr().err.strip().splitlines()
                assert len(err) == 1 and f"goal position {value}" in err[0], err
                assert "joint j1" in err[0] and f"ticks [{lo}, {hi}]" in err[0] and "nothing written" in err[0]
                assert bus.servo(2).get("goal") == before
        assert main([*base, "--addr", "117", "--size", "1", "--value", "3"]) == 4  # part of the goal register
        assert "overlaps GOAL_POSITION" in capsys.readouterr().err
        assert main([*base, "--register", "GOAL_POSITION", "--value", str(hi)]) == 0  # inside: written
        assert bus.servo(2).get("goal") == hi
        assert main([*base, "--register", "LED", "--value", "1"]) == 0  # other registers: unchecked
        assert main(["servo", "write", "--port", bus.port, "--id", "9", "--robot", "wbot", "--register",
                     "goal_position", "--value", "2048"]) == 2  # fmt: skip
        assert "servo id 9 is not in robot wbot" in capsys.readouterr().err


def test_a_raw_address_needs_its_width(tmp_path, capsys):
    """``--addr`` without ``--size`` read (and wrote) one byte of what may be a 4-byte register."""
    robot = make_robot(tmp_path)
    with VirtualBus(robot) as bus:
        before = bus.servo(1).get("goal")
        for verb in (["read"], ["write", "--value", "3"]):
            assert main(["servo", *verb, "--port", bus.port, "--id", "1", "--addr", "116"]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "--addr 116 needs --size 1, 2 or 4" in err[0], err
        assert bus.servo(1).get("goal") == before


def test_servo_write_refuses_a_goal_under_a_robot_file_the_servos_cannot_keep(tmp_path, monkeypatch, capsys):
    robot = make_robot(tmp_path, name="fastbot", v_max=6.0)
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    with VirtualBus(robot) as bus:
        before = bus.servo(2).get("goal")
        rc = main(["servo", "write", "--port", bus.port, "--id", "2", "--robot", "fastbot", "--register",
                   "GOAL_POSITION", "--value", str(before + 10)])  # fmt: skip
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 3 and len(err) == 1 and "not safe to move real servos with (nothing written)" in err[0], err
        assert bus.servo(2).get("goal") == before


# --- the reference pose and the shutdown ------------------------------------------------------------------------
def test_first_goal_after_connect_is_a_step_from_the_present_pose():
    """Moved by hand while torque was off: the first goal must be near where the robot is now, not where it was."""
    robot = SIM_ROBOT
    j = robot.joint_names.index("head_pan")
    b = MujocoBackend(robot)
    b.connect()
    try:
        b.set_torque(False)
        b.data.qpos[b.sim.qpos_idx[j]] = 0.6  # pushed by hand
        b.advance(0.0)
        here = b.read_positions()
        with pytest.raises(SafetyError, match=r"head_pan steps 0\.6\d* rad"):
            b.write_goal(robot.rest_q_rad)  # where it was at connect: a jump from where it is
        b.write_goal(here)
        b.set_torque(True)
        b.connect()  # reconnecting forgets the last goal: the reference is read again
        assert b.last_goal_rad is None
    finally:
        b.shutdown()
    np.testing.assert_allclose(b.log["goal_rad"][-1], robot.rest_q_rad, atol=1e-12)


def test_shutdown_outside_the_limits_turns_torque_off_without_an_unsafe_goal(tmp_path):
    """Torque on with the robot outside its limits and no goal sent: no guarded ramp exists, so shutdown writes no
    goal, says why, and still turns torque off."""
    robot = make_robot(tmp_path)
    start = np.array([robot.q_max_rad[0] + 0.3, 0.0, 0.0])
    with VirtualBus(robot, start_q_rad=start) as bus:
        log = GoalLog(bus)
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, health_hz=0)
        backend.connect()
        backend.set_torque(True)
        backend.shutdown()
        assert all(len(v) == 0 for v in log.ticks.values())
        assert not any(s.torque_on for s in bus.servos)
        assert any(
            e.startswith("shutdown: could not reach rest (unsafe goal") and "j0 steps" in e for e in backend.events
        ), backend.events


def test_servo_write_with_a_robot_guards_torque_speed_and_the_registers_the_yaml_manages(tmp_path, monkeypatch, capsys):
    robot = make_robot(tmp_path, name="wbot", v_max=0.5)
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    with VirtualBus(robot) as bus:
        be = get_backend_factory("dynamixel")(robot, port=bus.port)
        base = ["servo", "write", "--port", bus.port, "--id", "2", "--robot", "wbot"]
        for reg, value in (("HOMING_OFFSET", 1000), ("MAX_POSITION_LIMIT", 4095), ("OPERATING_MODE", 1),
                           ("PROFILE_VELOCITY", 0), ("ID", 7)):  # fmt: skip
            assert main([*base, "--register", reg, "--value", str(value)]) == 4
            assert f"with --robot, servo write takes only GOAL_POSITION, LED, TORQUE_ENABLE; {reg}" in (
                capsys.readouterr().err
            )
        # a goal goes with the servo's own speed cap and acceleration limit, from the joint's limits
        present = bus.servo(2).get("present")
        assert main([*base, "--register", "GOAL_POSITION", "--value", str(present)]) == 0
        assert bus.servo(2).get("profile_velocity") == be.speed_cap_units()[1] > 0
        assert bus.servo(2).get("profile_acceleration") == be.accel_cap_units()[1] > 0
        # torque on only with the goal near where the servo is (moved by hand while off, it would snap back)
        assert main([*base, "--register", "TORQUE_ENABLE", "--value", "1"]) == 0
        assert main([*base, "--register", "TORQUE_ENABLE", "--value", "0"]) == 0
        move_by_hand(bus, 2, present + 300)
        assert main([*base, "--register", "TORQUE_ENABLE", "--value", "1"]) == 4
        assert f"torque on would drive it from tick {present + 300} to its goal {present}" in capsys.readouterr().err
        assert not bus.servo(2).torque_on


def test_servo_write_and_read_speak_each_registers_encoding(tmp_path, capsys):
    robot = make_robot(tmp_path, family="feetech", protocol=0.0, name="ftbot")
    with VirtualBus(robot) as bus:
        base = ["--port", bus.port, "--id", "1", "--protocol", "sts", "--register", "HOMING_OFFSET"]
        assert main(["servo", "write", *base, "--value", "-100"]) == 0
        assert bus.servo(1).get("Homing_Offset") == -100  # sign-magnitude (sign in bit 11), as the servo reads it
        assert main(["servo", "read", *base]) == 0
        assert "HOMING_OFFSET = -100" in capsys.readouterr().out
        too_big = ["servo", "write", "--port", bus.port, "--id", "1", "--protocol", "sts"]
        assert main([*too_big, "--register", "MAX_POSITION_LIMIT", "--value", "65536"]) == 2
        assert "MAX_POSITION_LIMIT: value 65536 does not fit the 2-byte register (from 0 to 65535)" in (
            capsys.readouterr().err
        )
        assert bus.servo(1).get("max") == 4095


def test_servo_write_refuses_an_id_another_servo_has(tmp_path, capsys):
    robot = make_robot(tmp_path, name="idbot", n_joints=2)
    with VirtualBus(robot) as bus:
        assert main(["servo", "write", "--port", bus.port, "--id", "2", "--register", "ID", "--value", "1"]) == 2
        assert "id 1 is already taken" in capsys.readouterr().err
        assert sorted(s.id for s in bus.servos) == [1, 2]
