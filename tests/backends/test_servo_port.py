"""The serial link: late replies are never taken as answers to later requests; the port is exclusive."""

from __future__ import annotations

import time

import numpy as np
import pytest

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.player import play
from robogest.backends.servos.transport import collect_status_packets
from robogest.cli.main import main
from robogest.errors import BackendError
from robogest.robot.config import load_robot_config
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.conftest import sine_traj

CHAINS = [("dynamixel", 2.0), ("feetech", 0.0)]  # P1 has no sync read: one reply in flight, never late


@pytest.mark.parametrize(("family", "protocol"), CHAINS)
def test_late_replies_of_5_to_20_ms_cause_no_false_stop(tmp_path, family, protocol):
    """Replies delayed past their deadline used to be read as the answer to the next request
    ("temperature 195 °C", "supply voltage 591.8 V"); now they are skipped by id and length."""
    robot = make_robot(tmp_path, family=family, protocol=protocol, n_joints=4)
    with VirtualBus(robot, "delay=0.005:0.02/0.3,seed=2") as bus:
        backend = get_backend_factory(family)(robot, port=bus.port, health_hz=25)
        report = play(sine_traj(robot, seconds=2.0), backend, time_scale=2.0)
        delayed_past_deadline = backend.retry_count + backend.missed_reads
    assert report.completed, report.errors
    assert not any("temperature" in e or "voltage" in e for e in report.errors)
    assert delayed_past_deadline > 0  # the fault really made replies late
    assert backend.stale_replies > 0  # ... and late replies really arrived during later requests


def time_out_and_release_before_the_next_request(backend, bus: VirtualBus, monkeypatch, sid: int, reg) -> None:
    """Read ``reg`` of servo ``sid`` with its reply held back by the bus until the read has timed out, then have
    the backend's next request find that late reply ahead of its own answers (``monkeypatch.undo()`` ends it)."""
    bus.faults.delay_min_s = bus.faults.delay_max_s = 60.0  # held back by the bus
    bus.faults.delay_p = 1.0
    assert not backend._read_raw(sid, reg)[1]  # timed out; its reply is still queued
    bus.faults.delay_p = 0.0
    begin = backend.transport.begin

    def begin_then_release_the_late_reply(*args, **kwargs):
        k = begin(*args, **kwargs)
        with bus._lock:  # the late reply goes out now, ahead of the answers to this request
            bus._outq[0] = (time.monotonic(), *bus._outq[0][1:])
            bus._line_free_at = time.monotonic()
        return k

    monkeypatch.setattr(backend.transport, "begin", begin_then_release_the_late_reply)


def test_late_reply_of_the_same_length_is_never_used(tmp_path, monkeypatch):
    """A late Present Voltage reply (1 byte) must not answer a Present Temperature read (1 byte)."""
    robot = make_robot(tmp_path, family="feetech", protocol=0.0, n_joints=2)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory("feetech")(robot, port=bus.port)
        backend.connect()
        try:
            volt, temp = backend.REG["voltage"], backend.REG["temperature"]
            time_out_and_release_before_the_next_request(backend, bus, monkeypatch, 1, volt)
            value, ok, _, _ = backend._read_raw(1, temp)
            monkeypatch.undo()
            assert ok and value == bus.servo(1).get("temperature") != bus.servo(1).get("voltage")
            assert backend.stale_replies == 1  # the late voltage reply arrived first, and was skipped
        finally:
            backend.shutdown()


@pytest.mark.parametrize(("family", "protocol"), CHAINS)
def test_late_reply_to_the_same_read_does_not_make_a_sync_read_lose_servos(tmp_path, monkeypatch, family, protocol):
    """Servo 3's late position reply, arriving ahead of a sync read's answers, used to pass for its answer
    and (servos answer in order) make servos 1 and 2 look lost: two re-reads with no fault (CI, a starved
    machine). Now the read asks for one more byte, so the late reply has another length and is skipped."""
    robot = make_robot(tmp_path, family=family, protocol=protocol, n_joints=4)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        backend.connect()
        try:
            present = backend.REG["present"]
            time_out_and_release_before_the_next_request(backend, bus, monkeypatch, 3, present)
            retries = backend.retry_count
            got = backend._sync_read_raw(present, [1, 2, 3, 4])
            monkeypatch.undo()
            assert all(got[sid][1] for sid in (1, 2, 3, 4)), got
            assert backend.retry_count == retries and backend.stale_replies == 1
            q = backend.ticks_to_rad(np.array([got[sid][0] for sid in (1, 2, 3, 4)]))
            np.testing.assert_allclose(q, robot.rest_q_rad, atol=0.05)
        finally:
            backend.shutdown()


def test_delayed_feetech_connect_has_no_traceback(tmp_path):
    robot = make_robot(tmp_path, family="feetech", protocol=0.0, n_joints=2)
    with VirtualBus(robot, "delay=0.005:0.02,seed=1") as bus:
        backend = get_backend_factory("feetech")(robot, port=bus.port, retries=4)
        backend.connect()  # pings (Model Number reads) all answered late, none misread
        try:
            assert np.all(np.abs(backend.read_positions() - robot.rest_q_rad) < 0.05)
        finally:
            backend.shutdown()


@pytest.mark.parametrize(("family", "protocol"), CHAINS)
def test_second_client_gets_one_line_and_never_disturbs_the_first(tmp_path, family, protocol):
    robot = make_robot(tmp_path, family=family, protocol=protocol, n_joints=3)
    with VirtualBus(robot) as bus:
        first = get_backend_factory(family)(robot, port=bus.port)
        first.connect()
        try:
            first.set_torque(True)
            second = get_backend_factory(family)(robot, port=bus.port)
            with pytest.raises(BackendError, match=rf"^serial port {bus.port} is in use by another program"):
                second.connect()
            second.shutdown()  # must not reach the servos: torque stays on for the first client
            time.sleep(0.05)
            assert all(s.torque_on for s in bus.servos)
            assert np.all(np.isfinite(first.read_positions()))
        finally:
            first.shutdown()
        assert not any(s.torque_on for s in bus.servos)
        again = get_backend_factory(family)(robot, port=bus.port)  # released on close
        again.connect()
        again.shutdown()


def test_cli_on_a_busy_port_is_one_line(tmp_path, capsys):
    robot = make_robot(tmp_path, n_joints=2)
    with VirtualBus(robot) as bus:
        first = get_backend_factory("dynamixel")(robot, port=bus.port)
        first.connect()
        try:
            assert main(["servo", "ping", "--port", bus.port, "--id", "1"]) == 5
        finally:
            first.shutdown()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and bus.port in err[0] and "in use" in err[0]


def test_wrong_protocol_is_one_line_suggesting_scan(tmp_path, capsys):
    """Protocol 1.0 servos, robot YAML says 2.0: one line, not one per servo, and it names `servo scan`."""
    make_robot(tmp_path, family="dynamixel", protocol=1.0, n_joints=11, name="p1bot")
    yaml_p2 = make_robot(tmp_path / "p2", family="dynamixel", protocol=2.0, n_joints=11, name="p1bot")
    with VirtualBus(load_robot_config(tmp_path / "p1bot.yaml")) as bus:
        backend = get_backend_factory("dynamixel")(yaml_p2, port=bus.port, retries=0)
        with pytest.raises(BackendError) as e:
            backend.connect()
    msg = str(e.value)
    assert "\n" not in msg and f"robogest servo scan --port {bus.port}" in msg
    assert msg.startswith(f"no servo answered on {bus.port} at 1000000 baud with dynamixel protocol 2")


def test_collect_status_packets_skips_a_late_reply_of_another_length():
    # id 1's late 1-byte reply (8 bytes in all) arrives before its 2-byte answer to this read (9 bytes)
    stream = [([0, 1] + [0] * 6, True), ([0, 1] + [0] * 7, True), ([0, 2] + [0] * 7, True)]
    got = collect_status_packets([1, 2], lambda: stream.pop(0) if stream else ([], False), lambda: not stream,
                                 id_at=1, length=9)  # fmt: skip
    assert got == {1: [0, 1] + [0] * 7, 2: [0, 2] + [0] * 7}
