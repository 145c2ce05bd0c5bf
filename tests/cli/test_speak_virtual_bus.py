"""`robogest speak` on the shipped robots through the simulated servo bus and the real vendor SDKs."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import scservo_sdk as scs

from robogest.backends import get_backend_factory
from robogest.cli.main import main
from robogest.robot import find_robot
from robogest.virtualbus import VirtualBus

CASES = [
    ("humanoid_xl430", "dynamixel"),
    ("humanoid_sts3215", "feetech"),
    ("desk_arm_sts3215", "feetech"),
    ("so101_sts3215", "feetech"),
]


@pytest.fixture(autouse=True)
def _scs_end():
    yield
    scs.SCS_SETEND(0)  # the Feetech SDK keeps its byte order in a global


@pytest.mark.parametrize(("robot_name", "family"), CASES)
def test_speak_on_virtual_bus_ends_at_rest_with_torque_off(robot_name, family, capsys):
    robot = find_robot(robot_name)
    with VirtualBus(robot) as bus:
        assert main(["speak", "Hi, you!", "--robot", robot_name, "--backend", family, "--port", bus.port]) == 0
        time.sleep(0.05)
        rec = bus.record()
        goals = rec["goal_ticks"]
        assert np.all(goals >= rec["min_ticks"]) and np.all(goals <= rec["max_ticks"])
        assert np.ptp(goals, axis=0).max() > 40  # it gestured
        assert rec["torque_on"].any() and not rec["torque_on"][-1].any()
        assert not any(s.torque_on for s in bus.servos)
        backend = get_backend_factory(family)(robot, port=bus.port)
        rest = backend.rad_to_ticks(robot.rest_q_rad)[np.argsort(backend.ids)]
        np.testing.assert_allclose(rec["present_ticks"][-1], rest, atol=0.03 * 4096)
    assert "played" in capsys.readouterr().out


def test_ctrl_c_during_speak_exits_130_with_torque_off(monkeypatch, capsys):
    """Ctrl-C (a real SIGINT) half a second into the spoken motion: one error line, exit code 130, the robot back
    at rest with every servo's torque off."""
    import signal

    from robogest.trajectory import Trajectory

    sample = Trajectory.sample

    def ctrl_c_at_half_second(self, t_s):
        if t_s >= 0.5:
            signal.raise_signal(signal.SIGINT)
        return sample(self, t_s)

    monkeypatch.setattr(Trajectory, "sample", ctrl_c_at_half_second)
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot) as bus:
        rc = main(["speak", "Hello there, I wave while I talk.", "--backend", "dynamixel", "--port", bus.port])
        time.sleep(0.05)
        rec = bus.record()
        assert rc == 130 and capsys.readouterr().err.strip().splitlines() == ["robogest: interrupted"]
        assert rec["torque_on"].any() and not any(s.torque_on for s in bus.servos)
        backend = get_backend_factory("dynamixel")(robot, port=bus.port)
        rest = backend.rad_to_ticks(robot.rest_q_rad)[np.argsort(backend.ids)]
        np.testing.assert_allclose([bus.servo(int(i)).get("goal") for i in rec["servo_ids"]], rest, atol=1)


def test_speak_with_five_percent_faults_finishes_safely(capsys):
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot, "noreply=0.03,badcrc=0.02,seed=3") as bus:
        rc = main(["speak", "Hi, you!", "--backend", "dynamixel", "--port", bus.port])
        time.sleep(0.05)
        assert not any(s.torque_on for s in bus.servos)
        rec = bus.record()
        assert np.all(rec["goal_ticks"] >= rec["min_ticks"]) and np.all(rec["goal_ticks"] <= rec["max_ticks"])
    out = capsys.readouterr()
    if rc == 0:
        retries = int(out.out.split("bus retries ")[1].split(",")[0])
        assert retries > 0  # faults were met and retried, not ignored
    else:  # the retry budget ran out: a clear one-line report, torque off (checked above)
        assert rc == 5 and len(out.err.strip().splitlines()) == 1 and "servo" in out.err


def test_port_disconnect_mid_speech_stops_with_one_line(capsys):
    robot = find_robot("humanoid_sts3215")
    with VirtualBus(robot) as bus:

        def disconnect_once_moving() -> None:  # timed from the first torque-on, not from bus start (TTS may be slow)
            deadline = time.monotonic() + 60
            while not any(s.torque_on for s in bus.servos) and time.monotonic() < deadline:
                time.sleep(0.01)
            bus.faults.disconnect_at_s = bus.elapsed_s + 0.5

        watcher = threading.Thread(target=disconnect_once_moving, daemon=True)
        watcher.start()
        t0 = time.monotonic()
        rc = main(["speak", "Hello there, this sentence is long enough to be cut off.", "--robot", robot.name,
                   "--backend", "feetech", "--port", bus.port])  # fmt: skip
        elapsed = time.monotonic() - t0
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 5 and len(err) == 1 and "lost" in err[0]
    assert elapsed < 30  # it stopped instead of hanging (the 0.2 s figure is measured in the benchmark notes)
