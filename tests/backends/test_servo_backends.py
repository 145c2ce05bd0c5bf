"""Backends on the real SDKs against the simulated bus: connect -> play -> safe shutdown, and faults."""

from __future__ import annotations

import time

import numpy as np
import pytest

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.player import play
from robogest.errors import BackendError
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.conftest import sine_traj

FAMILIES = [("dynamixel", 2.0), ("dynamixel", 1.0), ("feetech", 0.0)]
FAST = 4.0  # trajectory seconds per wall second


def settle_record(bus: VirtualBus) -> dict:
    time.sleep(0.05)  # let the recorder take a sample after the last write
    return bus.record()


@pytest.mark.parametrize(("family", "protocol"), FAMILIES)
def test_play_trajectory_then_rest_and_torque_off(tmp_path, family, protocol):
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        report = play(sine_traj(robot), backend, time_scale=FAST)
        rec = settle_record(bus)
        assert report.completed and report.n_ticks >= 25
        goals = rec["goal_ticks"]
        assert np.all(goals >= rec["min_ticks"]) and np.all(goals <= rec["max_ticks"])
        assert np.ptp(goals, axis=0).min() > 50  # it really moved
        assert rec["torque_on"].any() and not rec["torque_on"][-1].any()
        assert not any(s.torque_on for s in bus.servos)
        rest_ticks = np.array([bus.servo(int(i)).get("goal") for i in rec["servo_ids"]])
        exp = backend.rad_to_ticks(robot.rest_q_rad)
        np.testing.assert_allclose(rest_ticks, exp[np.argsort(backend.ids)], atol=1)
        np.testing.assert_allclose(rec["present_ticks"][-1], rest_ticks, atol=0.03 * backend._tpr[0])


def test_rad_tick_mapping_roundtrip_and_direction(tmp_path):
    robot = make_robot(tmp_path, directions=[1, -1, 1])
    be = get_backend_factory("dynamixel")(robot, port="/dev/null")
    q = np.array([0.3, 0.3, -0.2])
    t = be.rad_to_ticks(q)
    assert t[0] > 2048 and t[1] < 2048  # direction flips the sense
    np.testing.assert_allclose(be.ticks_to_rad(t), q, atol=2 * np.pi / 4096)


def test_wrong_servo_family_names_the_robots_family(tmp_path):
    from robogest.errors import ConfigError

    robot = make_robot(tmp_path, family="feetech", protocol=0.0)
    with pytest.raises(
        ConfigError, match=r"has feetech servos \(bus.family in its YAML\), not dynamixel; use --backend feetech"
    ):
        get_backend_factory("dynamixel")(robot, port="/dev/null")


def test_model_mismatch_names_servo_and_models(tmp_path):
    bus_robot = make_robot(tmp_path / "bus", model="XM430-W350")
    robot = make_robot(tmp_path / "cfg", model="XL430-W250")
    with VirtualBus(bus_robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        with pytest.raises(BackendError, match=r"id 1 \(joint j0\): expected model XL430-W250 \(1060\), found 1020"):
            backend.connect()
        assert not backend.is_connected


def test_missing_servo_is_reported_by_id_and_joint(tmp_path):
    with VirtualBus(make_robot(tmp_path), "vanish=2@0") as bus:
        backend = get_backend_factory("dynamixel")(make_robot(tmp_path), port=bus.port, retries=1)
        with pytest.raises(BackendError, match=r"servo id 2 \(joint j1\).*after 2 attempts"):
            backend.connect()


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 2.0), ("feetech", 0.0)])
def test_five_percent_faults_finish_safely(tmp_path, family, protocol):
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot, "noreply=0.05,badcrc=0.05,seed=1") as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        try:
            report = play(sine_traj(robot), backend, time_scale=FAST)
        except BackendError as e:  # allowed: a clear, servo-naming stop
            assert "servo id" in str(e)
            report = e.report
        rec = settle_record(bus)
        assert report.retries > 0 and report.errors  # faults happened and were reported
        assert np.all(rec["goal_ticks"] >= rec["min_ticks"]) and np.all(rec["goal_ticks"] <= rec["max_ticks"])
        assert not any(s.torque_on for s in bus.servos)
        assert any("injected" in e for e in bus.errors)


def test_port_disconnect_mid_play_stops_with_clear_error(tmp_path):
    robot = make_robot(tmp_path)
    with VirtualBus(robot, "disconnect@0.4") as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        with pytest.raises(BackendError, match=r"serial port .* lost") as ei:
            play(sine_traj(robot, seconds=4.0), backend, time_scale=FAST)
        assert backend.torque_off_attempted and not backend.is_connected
        assert not ei.value.report.completed


def test_hardware_error_mid_play_names_servo_and_turns_torque_off(tmp_path):
    robot = make_robot(tmp_path, family="feetech", protocol=0)
    with VirtualBus(robot, "hwerror=3:overheating@0.3") as bus:
        backend = get_backend_factory("feetech")(robot, port=bus.port)
        with pytest.raises(BackendError, match=r"servo id 3 \(joint j2\) reports overheating"):
            play(sine_traj(robot), backend, time_scale=FAST)
        assert not any(s.torque_on for s in bus.servos)


def test_exception_in_the_middle_still_turns_torque_off(tmp_path, monkeypatch):
    robot = make_robot(tmp_path)
    traj = sine_traj(robot)
    calls = {"n": 0}
    original = traj.sample

    def boom(t):
        calls["n"] += 1
        if calls["n"] == 10:
            raise RuntimeError("generator bug")
        return original(t)

    monkeypatch.setattr(traj, "sample", boom)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        with pytest.raises(RuntimeError, match="generator bug"):
            play(traj, backend, time_scale=FAST)
        rec = settle_record(bus)
        assert rec["torque_on"].any() and not any(s.torque_on for s in bus.servos)
        assert backend.torque_off_attempted


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 2.0), ("feetech", 0.0)])
def test_ctrl_c_mid_play_goes_to_rest_and_turns_torque_off(tmp_path, family, protocol):
    """A real SIGINT (what Ctrl-C sends) one second into the motion: KeyboardInterrupt reaches the caller, and on
    the way the robot ramps to rest and every servo's torque is turned off."""
    import signal

    robot = make_robot(tmp_path, family=family, protocol=protocol)

    def ctrl_c_at_1s(t_s: float, _duration_s: float) -> None:
        if t_s >= 1.0:
            signal.raise_signal(signal.SIGINT)

    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        with pytest.raises(KeyboardInterrupt):
            play(sine_traj(robot, seconds=4.0), backend, time_scale=FAST, progress=ctrl_c_at_1s)
        rec = settle_record(bus)
        assert rec["torque_on"].any() and not any(s.torque_on for s in bus.servos)
        assert backend.torque_off_attempted and not backend.is_connected
        rest_ticks = np.array([bus.servo(int(i)).get("goal") for i in rec["servo_ids"]])
        np.testing.assert_allclose(rest_ticks, backend.rad_to_ticks(robot.rest_q_rad)[np.argsort(backend.ids)], atol=1)


def test_health_threshold_stops_safely(tmp_path):
    robot = make_robot(tmp_path)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, max_temperature_c=20.0, health_hz=50.0)
        with pytest.raises(BackendError, match=r"temperature 30 °C above the 20 °C limit"):
            play(sine_traj(robot), backend, time_scale=FAST)
        assert not any(s.torque_on for s in bus.servos)
