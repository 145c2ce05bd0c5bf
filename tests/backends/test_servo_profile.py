"""The servos' own acceleration limit (Dynamixel X Profile Acceleration, MX-28 Goal Acceleration, Feetech STS ACC),
set at connect from the robot YAML and read back, through the real SDKs against the simulated bus: a goal that
arrives late or after a lost write no longer makes the servo accelerate past the joint's limit."""

from __future__ import annotations

import time

import numpy as np
import pytest

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.player import play
from robogest.backends.servos.bus import ACCEL_CAP_MARGIN
from robogest.errors import BackendError
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot, monologue, servo_acceleration_ratio

CHAINS = [("dynamixel", 2.0), ("feetech", 0.0)]


@pytest.mark.parametrize(
    ("family", "protocol", "model", "a_max", "reg"),
    [
        ("dynamixel", 2.0, "XL430-W250", 40.0, "PROFILE_ACCELERATION"),
        ("dynamixel", 1.0, "MX-28", 20.0, "GOAL_ACCELERATION"),
        ("feetech", 0.0, "STS3215", 20.0, "ACCELERATION"),
        ("feetech", 0.0, "STS3215", 60.0, "ACCELERATION"),  # above what the register holds (254 units): its top
    ],
)
def test_connect_writes_and_reads_back_each_servos_own_acceleration_limit(tmp_path, family, protocol, model, a_max,
                                                                          reg):  # fmt: skip
    robot = make_robot(tmp_path, family=family, protocol=protocol, model=model, a_max=a_max)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        reads: list[str] = []
        read = backend.read_register
        backend.read_register = lambda sid, r: reads.append(r.name) or read(sid, r)
        backend.connect()
        held = np.array([bus.servo(int(sid)).get("profile_acceleration") for sid in backend.ids])
        backend.shutdown()
    assert backend.REG["acceleration"].name == reg
    np.testing.assert_array_equal(held, backend.accel_cap_units())
    assert reads.count(reg) == len(backend.ids)  # each one read back
    servo_a = held * np.array([m.accel_unit_rad_s2 for m in backend.models])  # rad/s² (gear ratio 1)
    top = np.array([m.accel_max_units for m in backend.models])
    assert np.all(servo_a <= ACCEL_CAP_MARGIN * a_max)
    # as close to the limit as the unit allows, or the register's top
    assert np.all((servo_a >= a_max) | (held == top)), servo_a
    assert np.all(servo_a >= 0.9 * min(a_max, top[0] * backend.models[0].accel_unit_rad_s2))


def test_acceleration_limit_goes_through_the_gear_and_never_writes_0(tmp_path):
    """The limit is at the servo's horn (joint limit times the gear ratio), and a limit below one unit still writes
    1: 0 would mean no limit at all."""
    robot = make_robot(tmp_path, a_max=10.0)
    backend = get_backend_factory("dynamixel")(robot, port="/dev/null")
    unit = backend.models[0].accel_unit_rad_s2
    backend._gear = np.array([1.0, -3.0, 1.0])
    units = backend.accel_cap_units()
    assert units[0] == int(ACCEL_CAP_MARGIN * 10.0 / unit) and units[1] == int(ACCEL_CAP_MARGIN * 30.0 / unit)
    slow = make_robot(tmp_path, a_max=0.05, name="slowbot")  # rad/s², below one X-series unit (0.37 rad/s²)
    assert get_backend_factory("dynamixel")(slow, port="/dev/null").accel_cap_units().tolist() == [1, 1, 1]


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 1.0), ("feetech", 1.0)])
def test_models_without_an_acceleration_register_keep_the_limit_in_the_goal_stream(tmp_path, family, protocol):
    """AX-12A and SCS0009 have no acceleration register: nothing is written there, and connect goes on."""
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        writes: list[str] = []
        write = backend.write_register
        backend.write_register = lambda sid, r, v: writes.append(r.name) or write(sid, r, v)
        backend.connect()
        backend.shutdown()
        held = [bus.servo(int(sid)).get("profile_acceleration") if bus.servos[0].has("profile_acceleration") else 0
                for sid in backend.ids]  # fmt: skip
    assert not backend.accel_cap_units().any() and held == [0, 0, 0]
    assert backend.REG["acceleration"].name not in writes
    assert backend.REG["speed_cap"].name in writes  # the speed cap is still set


@pytest.mark.parametrize(("family", "protocol", "reg"), [("dynamixel", 2.0, "PROFILE_ACCELERATION"),
                                                         ("feetech", 0.0, "ACCELERATION")])  # fmt: skip
def test_a_servo_that_does_not_keep_its_acceleration_limit_is_refused(tmp_path, family, protocol, reg):
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot) as bus:
        servo = bus.servo(2)
        addr = servo.spec.reg("profile_acceleration").addr
        write = servo.write
        servo.write = lambda a, data: 0 if a == addr else write(a, data)  # answers OK, keeps nothing
        backend = get_backend_factory(family)(robot, port=bus.port)
        units = backend.accel_cap_units()[1]
        with pytest.raises(BackendError, match=rf"servo id 2 \(joint j1\): register {reg} reads back 0 after {units} "
                                               r"was written.*check its model and firmware"):  # fmt: skip
            backend.connect()
        assert not backend.is_connected and not any(s.torque_on for s in bus.servos)


def _stall_every(backend, n: int, stall_s: float) -> None:
    """Every ``n``-th position read of ``backend`` takes ``stall_s`` longer (a starved machine): a late goal."""
    read, count = backend.read_positions, [0]

    def slow():
        count[0] += 1
        if count[0] % n == 0:
            time.sleep(stall_s)
        return read()

    backend.read_positions = slow


@pytest.mark.parametrize(("family", "protocol"), CHAINS)
@pytest.mark.parametrize("fault", ["lost", "late"])
def test_servos_own_acceleration_stays_within_1_1x_the_limit_when_goals_are_lost_or_late(tmp_path, family, protocol,
                                                                                      fault):  # fmt: skip
    """With 5 % of the instructions lost (sync writes of goals among them) or a 150 ms stall every 0.4 s, the servo
    met the next goal at 2.7-3.6x the joint's acceleration limit without its own limit (the goals keep the limit,
    but a late or lost goal is a step the servo covered at once); with it, at most 1.1x."""
    robot = make_robot(tmp_path, family=family, protocol=protocol)
    with VirtualBus(robot, "drop=0.05,seed=2" if fault == "lost" else None) as bus:
        # a servo is declared lost after 1 s, not 0.15 s: this test is about its motion, not a starved test machine
        backend = get_backend_factory(family)(robot, port=bus.port, health_hz=0, lost_after_s=1.0)
        if fault == "late":
            _stall_every(backend, 20, 0.15)
        report = play(monologue(robot, 2.5, fps=30.0), backend, rate_hz=50.0)
        time.sleep(0.05)
        rec = bus.record()
    assert report.completed
    if fault == "lost":
        assert any("SYNC_WRITE" in e and "lost" in e for e in rec["errors"])
    else:
        assert report.skipped_slots > 0
    assert np.ptp(rec["position_ticks"], axis=0).min() > 200  # every servo really moved
    ratio = servo_acceleration_ratio(rec, robot)
    assert ratio.max() <= ACCEL_CAP_MARGIN, ratio
