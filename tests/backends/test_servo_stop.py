"""The way out, through the real SDKs against the simulated bus: a fault, a signal or a lost packet at the wrong
moment still ends with every answering servo at rest and torque off, and the servos' own speed cap is set."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

import robogest.backends.servos.dynamixel as dxl_backend
import robogest.backends.servos.feetech as ft_backend
from robogest.backends.base import get_backend_factory
from robogest.backends.control import ControlLoop
from robogest.backends.player import play
from robogest.backends.servos.bus import SPEED_CAP_MARGIN
from robogest.backends.signals import signals_end_at_rest
from robogest.errors import BackendError
from robogest.trajectory.types import Trajectory
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.conftest import sine_traj

RAISED = 0.85  # rad on every joint: far enough from rest (0) that torque off there would drop the arm


def hold(robot, seconds: float) -> Trajectory:
    t = np.arange(0.0, seconds, 0.02)
    return Trajectory(
        t_s=t, q_rad=np.full((len(t), len(robot.joints)), RAISED), joint_names=robot.joint_names,
        q_min_rad=robot.q_min_rad, q_max_rad=robot.q_max_rad, v_max_rad_s=robot.v_max_rad_s,
        a_max_rad_s2=robot.a_max_rad_s2, rest_q_rad=robot.rest_q_rad, silent=np.zeros(len(t), bool),
    )  # fmt: skip


def present_rad(bus: VirtualBus, backend) -> np.ndarray:
    return backend.ticks_to_rad(np.array([bus.servo(int(i)).get("present") for i in backend.ids]))


@pytest.mark.parametrize(
    ("fault", "faulty", "match"),
    [
        ("heat", 2, r"servo id 2 \(joint j1\): temperature 75 °C above the 65 °C limit"),
        ("hwerror=2:overload@0.6", 2, r"servo id 2 \(joint j1\) reports hardware error: overload"),
        ("vanish=3@0.6", 3, r"servo id 3 \(joint j2\): lost"),
    ],
)
def test_a_servo_fault_mid_gesture_still_takes_the_others_to_rest_before_torque_off(tmp_path, fault, faulty, match):
    """Health readings past a limit, hardware-error flags and a lost servo stop the motion; the glide to rest that
    follows must not be cut short by the same fault, read again on its way (that turned torque off with the arms
    raised)."""
    robot = make_robot(tmp_path, v_max=1.0, a_max=5.0)
    with VirtualBus(robot, "" if fault == "heat" else fault, start_q_rad=np.full(3, RAISED)) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port, health_hz=10.0)

        def heat(t_s: float, _d: float) -> None:
            if fault == "heat" and t_s > 0.5:
                bus.servo(2).motion.temp_c = 75.0

        with pytest.raises(BackendError, match=match):
            play(hold(robot, 4.0), backend, progress=heat)
        time.sleep(0.05)
        answering = [k for k, sid in enumerate(backend.ids) if sid != faulty or fault == "heat"]
        np.testing.assert_allclose(present_rad(bus, backend)[answering], robot.rest_q_rad[answering], atol=0.02)
        assert not any(bus.servo(int(backend.ids[k])).torque_on for k in answering)
        assert any("during the glide to rest" in e for e in backend.events) or fault == "heat"


@pytest.mark.parametrize("family", ["dynamixel", "feetech"])
def test_a_signal_while_torque_goes_off_servo_by_servo_waits_until_every_servo_is_off(tmp_path, monkeypatch, family):
    module = dxl_backend.DynamixelBackend if family == "dynamixel" else ft_backend.FeetechBackend
    write = module.write_register

    def signal_after_the_first_torque_off(self, sid, reg, value):
        write(self, sid, reg, value)
        if reg is self.REG["torque"] and value == 0 and sid == 1:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(module, "write_register", signal_after_the_first_torque_off)
    robot = make_robot(tmp_path, family=family, protocol=2.0 if family == "dynamixel" else 0.0)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        with pytest.raises(KeyboardInterrupt, match="SIGTERM; the robot went to rest and torque is off"):
            play(sine_traj(robot, seconds=1.0), backend, time_scale=4.0)
        time.sleep(0.05)
        assert not any(s.torque_on for s in bus.servos)


def test_a_signal_during_a_backends_own_shutdown_waits_until_every_servo_is_off(tmp_path, monkeypatch):
    """The same without a control loop: a backend used directly (``with backend:``) shuts down by itself."""
    write = dxl_backend.DynamixelBackend.write_register

    def signal_after_the_first_torque_off(self, sid, reg, value):
        write(self, sid, reg, value)
        if reg is self.REG["torque"] and value == 0 and sid == 1:
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(dxl_backend.DynamixelBackend, "write_register", signal_after_the_first_torque_off)
    robot = make_robot(tmp_path)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        with signals_end_at_rest(), pytest.raises(KeyboardInterrupt), backend:
            backend.set_torque(True)
        time.sleep(0.05)
        assert not any(s.torque_on for s in bus.servos)


def test_a_lost_hold_goal_is_sent_again_before_torque_goes_on(tmp_path, monkeypatch):
    """A sync write gets no reply: if the hold goal is lost, a servo would switch torque on towards whatever goal
    it still holds (here the rest pose, with the joints sagged 0.7 rad from it) at full speed."""
    sync_write = ft_backend.FeetechBackend._sync_write_raw
    dropped = []

    def lose_the_first_goal(self, reg, values):
        if reg is self.REG["goal"] and not dropped:
            dropped.append(values)
            return None
        return sync_write(self, reg, values)

    monkeypatch.setattr(ft_backend.FeetechBackend, "_sync_write_raw", lose_the_first_goal)
    robot = make_robot(tmp_path, family="feetech", protocol=0.0, v_max=2.0, a_max=10.0)
    with VirtualBus(robot, start_q_rad=np.full(3, 0.7)) as bus:
        backend = get_backend_factory("feetech")(robot, port=bus.port)
        rest = backend.rad_to_ticks(robot.rest_q_rad)
        for k, sid in enumerate(backend.ids):  # the goal registers still hold the last session's rest pose
            servo = bus.servo(int(sid))
            servo._store(servo.spec.reg("goal"), int(rest[k]))
        loop = ControlLoop(backend, 50.0, threaded=False).start()
        before = present_rad(bus, backend)
        loop.run_for(0.3)
        moved = np.abs(present_rad(bus, backend) - before).max()
        loop.close()
    assert dropped and moved < 0.01
    assert any("goal sent again" in e for e in backend.events)


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 2.0), ("dynamixel", 1.0), ("feetech", 0.0)])
def test_connect_caps_each_servos_own_speed_at_its_joints_limit(tmp_path, family, protocol):
    robot = make_robot(tmp_path, family=family, protocol=protocol, v_max=1.0)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        backend.connect()
        caps = np.array([bus.servo(int(sid)).get("profile_velocity") for sid in backend.ids])
        unit = np.array([m.speed_unit_rad_s for m in backend.models])
        backend.shutdown()
    np.testing.assert_allclose(caps * unit, robot.v_max_rad_s * SPEED_CAP_MARGIN, rtol=0.03)


def test_at_a_low_control_rate_the_servo_keeps_near_the_velocity_limit_between_goals(tmp_path):
    """Goals 0.5 s apart keep the limit on average; without the servo's own cap each step was covered at the
    servo's top speed (6.4 rad/s for a 1 rad/s joint)."""
    robot = make_robot(tmp_path, v_max=1.0, a_max=10.0)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        play(sine_traj(robot, seconds=3.0, amp=0.8), backend, rate_hz=2.0)
        time.sleep(0.05)
        rec = bus.record()
    q = (rec["present_ticks"] - 2048) / backend._tpr[0]  # (N, J) servo radians
    # Speed over steps of at least 50 ms: one tick of rounding over a sample interval shortened by a busy machine
    # read as 1.62x once; the servo's top speed (6.4x) is what this guards against.
    keep = [0]
    for i, t in enumerate(rec["t_s"]):
        if t - rec["t_s"][keep[-1]] >= 0.05:
            keep.append(i)
    v = np.abs(np.diff(q[keep], axis=0)) / np.diff(rec["t_s"][keep])[:, None]
    assert v.max() < 1.6 * robot.v_max_rad_s.max()


@pytest.mark.parametrize(
    ("family", "protocol", "register", "value", "match"),
    [
        ("dynamixel", 2.0, "Operating_Mode", 1, r"servo id 2 \(joint j1\): Operating Mode \(register 11\) is 1"),
        ("dynamixel", 2.0, "Drive_Mode", 1, r"servo id 2 \(joint j1\): Drive Mode .*reverse bit"),
        ("dynamixel", 2.0, "Drive_Mode", 4, r"servo id 2 \(joint j1\): Drive Mode .*Profile Velocity a time"),
        ("feetech", 0.0, "Operating_Mode", 1, r"servo id 2 \(joint j1\): Operating Mode \(register 33\) is 1"),
        ("dynamixel", 1.0, "wheel", 0, r"servo id 2 \(joint j1\): both position-limit registers are 0.*wheel"),
    ],
)
def test_connect_refuses_a_servo_not_in_position_mode(tmp_path, family, protocol, register, value, match):
    """Goals are angles only in a position mode; in speed (wheel) mode a servo would take its speed cap as the
    speed to turn at, and Dynamixel's reverse bit would mirror the joint on top of the YAML's direction."""
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        servo = bus.servo(2)
        names = ["CW_Angle_Limit", "CCW_Angle_Limit"] if register == "wheel" else [register]
        for name in names:
            servo._store(servo.spec.reg(name), value)
        backend = get_backend_factory(family)(robot, port=bus.port, check_limits=False)
        with pytest.raises(BackendError, match=match):
            backend.connect()
        assert not backend.is_connected and not any(s.torque_on for s in bus.servos)
