"""`robogest speak` on the shipped robots through the simulated servo bus and the real vendor SDKs."""

from __future__ import annotations

import re
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


#: Plain progress lines (`robogest.cli.progress`) a piped stderr gets during a long command; not error lines.
PROGRESS_LINE = re.compile(r"^robogest: [\w +]+: \d+% \(")


def _signal_at(monkeypatch, signum, t_s: float = 0.5):
    """Make Trajectory.sample raise a real ``signum`` once the motion reaches ``t_s``."""
    import signal

    from robogest.trajectory import Trajectory

    sample = Trajectory.sample
    sent = []
    # the CLI keeps ignoring a hangup its parent ignored (as under ``nohup``); this test is about the default
    if signal.getsignal(signum) is signal.SIG_IGN:
        signal.signal(signum, signal.SIG_DFL)

    def sample_and_signal(self, t):
        if t >= t_s and not sent:
            sent.append(t)
            signal.raise_signal(signum)
        return sample(self, t)

    monkeypatch.setattr(Trajectory, "sample", sample_and_signal)


def _assert_at_rest_torque_off(bus, robot) -> np.ndarray:
    time.sleep(0.05)
    rec = bus.record()
    assert rec["torque_on"].any() and not any(s.torque_on for s in bus.servos)
    backend = get_backend_factory("dynamixel")(robot, port=bus.port)
    rest = backend.rad_to_ticks(robot.rest_q_rad)[np.argsort(backend.ids)]
    np.testing.assert_allclose([bus.servo(int(i)).get("goal") for i in rec["servo_ids"]], rest, atol=1)
    return rec


@pytest.mark.usefixtures("quit_does_not_dump_core")
@pytest.mark.parametrize(("name", "code"), [("SIGINT", 130), ("SIGTERM", 143), ("SIGHUP", 129), ("SIGQUIT", 131)])
def test_signal_during_speak_ends_at_rest_with_torque_off_and_one_line(name, code, monkeypatch, capsys):
    """Ctrl-C, kill, the terminal/SSH session closing, or Ctrl-\\ half a second into the motion: one line naming
    the signal, exit code 128 + signum, the robot back at rest with every servo's torque off."""
    import signal

    _signal_at(monkeypatch, getattr(signal, name))
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot) as bus:
        rc = main(["speak", "Hello there, I wave while I talk.", "--backend", "dynamixel", "--port", bus.port])
        _assert_at_rest_torque_off(bus, robot)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == code
    assert err == [f"robogest: interrupted by {name}; the robot went to rest and torque is off"]


def test_second_interrupt_during_the_glide_does_not_drop_the_arms(monkeypatch, capsys):
    """SIGTERM, then Ctrl-C while gliding to rest: the glide goes on (already as fast as the limits allow) to
    rest, then torque off; the goals sent stay within the per-tick velocity limit throughout."""
    import signal

    from robogest.backends.servos.dynamixel import DynamixelBackend

    _signal_at(monkeypatch, signal.SIGTERM)
    write = DynamixelBackend.write_goal
    after: list[np.ndarray] = []

    def write_and_interrupt(self, q, **kw):
        from robogest.backends import signals

        if signals._SIG.fired is not None:
            after.append(np.array(q, dtype=float))
            if len(after) == 3:
                signal.raise_signal(signal.SIGINT)
        return write(self, q, **kw)

    monkeypatch.setattr(DynamixelBackend, "write_goal", write_and_interrupt)
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot) as bus:
        rc = main(["speak", "Hello there, I wave while I talk.", "--backend", "dynamixel", "--port", bus.port])
        _assert_at_rest_torque_off(bus, robot)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 143 and err == ["robogest: interrupted by SIGTERM; the robot went to rest and torque is off"]
    assert len(after) > 3  # the glide went on after the second signal
    steps = np.abs(np.diff(np.array(after), axis=0))
    assert np.all(steps <= robot.v_max_rad_s / 50.0 + 1e-9)
    np.testing.assert_allclose(after[-1], robot.rest_q_rad, atol=1e-6)


def test_interrupt_when_the_bus_is_gone_says_rest_was_not_reached(monkeypatch, capsys):
    import signal

    from robogest.backends.servos.dynamixel import DynamixelBackend
    from robogest.errors import BackendError

    _signal_at(monkeypatch, signal.SIGTERM)
    send = DynamixelBackend._send_goal

    def send_or_fail(self, q):
        from robogest.backends import signals

        if signals._SIG.fired is not None:
            raise BackendError("serial port lost while sync writing GOAL_POSITION")
        return send(self, q)

    monkeypatch.setattr(DynamixelBackend, "_send_goal", send_or_fail)
    robot = find_robot("humanoid_xl430")
    with VirtualBus(robot) as bus:
        rc = main(["speak", "Hello there, I wave while I talk.", "--backend", "dynamixel", "--port", bus.port])
        time.sleep(0.05)
        assert not any(s.torque_on for s in bus.servos)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 143 and len(err) == 1
    assert err[0].startswith("robogest: interrupted by SIGTERM; the robot could not reach rest (")
    assert "serial port lost" in err[0] and err[0].endswith("torque off attempted")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["SIGINT", "SIGHUP", "SIGQUIT"])
def test_signal_to_a_background_process_ends_at_rest(name, tmp_path):
    """A background ``robogest speak`` (started with SIGINT ignored, as a shell's ``&`` does) gets ``name``
    mid-motion: it still glides to rest, turns torque off, prints one line and exits with 128 + signum."""
    import os
    import signal
    import subprocess
    import sys

    robot = find_robot("humanoid_xl430")
    text = "Hello there, this is a long sentence, so I keep waving my arms while I am talking to you."
    with VirtualBus(robot) as bus:
        proc = subprocess.Popen(
            [sys.executable, "-m", "robogest", "speak", text, "--backend", "dynamixel", "--port", bus.port],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=lambda: (signal.signal(signal.SIGINT, signal.SIG_IGN),  # as a shell's `&` does
                                signal.signal(signal.SIGHUP, signal.SIG_DFL)),  # as a terminal leaves it (not nohup)
            env={**os.environ},
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 120
            while not bus.record()["torque_on"].any():  # wait until it moves
                assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
                time.sleep(0.1)
            time.sleep(0.8)
            proc.send_signal(getattr(signal, name))
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        _assert_at_rest_torque_off(bus, robot)
    assert proc.returncode == 128 + getattr(signal, name)
    lines = [ln for ln in err.strip().splitlines() if not PROGRESS_LINE.match(ln)]  # stderr is a pipe: progress
    assert lines == [f"robogest: interrupted by {name}; the robot went to rest and torque is off"]


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


@pytest.mark.parametrize(("robot_name", "family"), CASES[:2])
def test_torque_lost_mid_speech_stops_glides_the_others_to_rest_and_names_the_servo(robot_name, family, capsys):
    """A second client (or a brownout) switches the left shoulder's torque off half a second into the motion: one
    line naming it, exit 5, the servos still holding torque glide to rest, every torque off; the limp one is never
    switched back on (it played on for 10 s and exited 0, the joints left limp away from rest)."""
    robot = find_robot(robot_name)
    sid = robot.bus.servos["l_shoulder_pitch"].id
    with VirtualBus(robot) as bus:
        cut: list[float] = []

        def torque_off_once_moving() -> None:  # timed from the first torque-on, not from bus start (TTS may be slow)
            deadline = time.monotonic() + 60
            while not any(s.torque_on for s in bus.servos) and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.5)
            cut.append(bus.elapsed_s)
            bus.inject_now("torqueoff", sid)

        watcher = threading.Thread(target=torque_off_once_moving, daemon=True)
        watcher.start()
        rc = main(["speak", "Hello there, this sentence is long enough to be cut off.", "--robot", robot_name,
                   "--backend", family, "--port", bus.port])  # fmt: skip
        watcher.join()
        time.sleep(0.05)
        rec = bus.record()
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 5 and len(err) == 1, err
    assert err[0].startswith(f"robogest: error: servo id {sid} (joint l_shoulder_pitch): torque found off")
    k = list(rec["servo_ids"]).index(sid)
    after = rec["t_s"] >= cut[0] + 0.01
    assert not rec["torque_on"][after, k].any()  # never switched back on
    assert not rec["torque_on"][-1].any()
    backend = get_backend_factory(family)(robot, port=bus.port)
    rest = backend.rad_to_ticks(robot.rest_q_rad)[np.argsort(backend.ids)]
    others = np.arange(len(rest)) != k
    np.testing.assert_allclose(rec["present_ticks"][-1][others], rest[others], atol=0.03 * 4096)
