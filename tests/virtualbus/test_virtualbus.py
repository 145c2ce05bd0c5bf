"""The simulated bus, driven through the real vendor SDKs (dynamixel_sdk, scservo_sdk) and raw bytes."""

from __future__ import annotations

import time

import dynamixel_sdk as dxl
import numpy as np
import pytest
import scservo_sdk as scs
import serial

from robogest.errors import InputError
from robogest.virtualbus import FaultSpec, VirtualBus
from robogest.virtualbus.framing import Parser1, Parser2, build2, crc16
from robogest.virtualbus.testing import make_robot


@pytest.fixture
def scs_end():
    """scservo_sdk keeps byte order in a module global: restore it after each test."""
    yield
    scs.SCS_SETEND(0)


def _dxl(bus: VirtualBus, protocol: float, baud: int = 1_000_000):
    port = dxl.PortHandler(bus.port)
    assert port.openPort() and port.setBaudRate(baud)
    return port, dxl.PacketHandler(protocol)


def test_crc_matches_known_ping_packet():
    ping = bytes.fromhex("FFFFFD00010300011 94E".replace(" ", ""))
    assert crc16(ping[:-2]) == 0x4E19
    assert Parser2().feed(ping)[0].inst == 0x01


def test_crc_agrees_with_sdk_on_random_packets():
    rng = np.random.default_rng(0)
    ph = dxl.PacketHandler(2.0)
    for _ in range(50):
        data = rng.integers(0, 256, size=int(rng.integers(1, 64))).tolist()
        assert crc16(bytes(data)) == ph.updateCRC(0, data, len(data))


def test_status_packet_is_byte_stuffed_and_parses_back():
    pkt = build2(1, 0, bytes([0xFF, 0xFF, 0xFD, 0x01]))
    assert b"\xff\xff\xfd\xfd" in pkt[7:]  # stuffed payload
    assert pkt[-2:] == crc16(pkt[:-2]).to_bytes(2, "little")


def test_p1_parser_resyncs_after_garbage():
    good = bytes([0xFF, 0xFF, 0x01, 0x02, 0x01, (~(1 + 2 + 1)) & 0xFF])
    pkts = Parser1().feed(b"\x00\xff\x13" + good + good)
    assert [p.servo_id for p in pkts] == [1, 1] and all(p.crc_ok for p in pkts)


def test_p2_ping_read_write_through_sdk(tmp_path):
    robot = make_robot(tmp_path)
    with VirtualBus(robot, return_delay_time=None) as bus:
        port, ph = _dxl(bus, 2.0)
        assert ph.ping(port, 1) == (1060, dxl.COMM_SUCCESS, 0)
        assert ph.read1ByteTxRx(port, 1, 6)[0] == 46  # firmware
        assert ph.read1ByteTxRx(port, 1, 9)[0] == 250  # return delay as shipped
        assert 110 <= ph.read2ByteTxRx(port, 1, 144)[0] <= 130  # ~12 V
        assert 25 <= ph.read1ByteTxRx(port, 1, 146)[0] <= 35  # ~30 °C
        assert ph.write1ByteTxRx(port, 1, 64, 1) == (dxl.COMM_SUCCESS, 0)
        assert ph.write4ByteTxRx(port, 1, 116, 2500) == (dxl.COMM_SUCCESS, 0)
        deadline = time.monotonic() + 2.0
        while abs(ph.read4ByteTxRx(port, 1, 132)[0] - 2500) > 3 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert abs(ph.read4ByteTxRx(port, 1, 132)[0] - 2500) <= 3
        assert ph.ping(port, 9)[1] == dxl.COMM_RX_TIMEOUT  # no such servo
        port.closePort()


def test_p2_read_only_and_torque_locked_eeprom_give_access_error(tmp_path):
    with VirtualBus(make_robot(tmp_path)) as bus:
        port, ph = _dxl(bus, 2.0)
        assert ph.write4ByteTxRx(port, 1, 132, 100) == (dxl.COMM_SUCCESS, 0x07)  # Present Position is R
        assert ph.write4ByteTxRx(port, 1, 48, 3000) == (dxl.COMM_SUCCESS, 0)  # EEPROM, torque off: fine
        ph.write1ByteTxRx(port, 1, 64, 1)
        assert ph.write4ByteTxRx(port, 1, 48, 4000) == (dxl.COMM_SUCCESS, 0x07)  # torque on locks EEPROM
        assert ph.read4ByteTxRx(port, 1, 48)[0] == 3000
        assert ph.write4ByteTxRx(port, 1, 116, 3500) == (dxl.COMM_SUCCESS, 0x04)  # past Max Position Limit
        assert ph.write2ByteTxRx(port, 1, 116, 5) == (dxl.COMM_SUCCESS, 0x05)  # half a register
        assert any("access error" in e for e in bus.errors)
        port.closePort()


def test_p2_broadcast_ping_answers_in_id_order(tmp_path):
    robot = make_robot(tmp_path, ids=[7, 2, 5])
    with VirtualBus(robot) as bus:
        ser = serial.Serial(bus.port, 1_000_000, timeout=0.2)
        ping = bytes.fromhex("FFFFFD00FE030001")
        ser.write(ping + crc16(ping).to_bytes(2, "little"))
        time.sleep(0.1)
        raw = ser.read(4096)
        ser.close()
    ids = [p.servo_id for p in Parser2().feed(raw)]
    assert ids == [2, 5, 7]


def test_p2_sdk_broadcast_ping_sync_and_fast_sync(tmp_path):
    with VirtualBus(make_robot(tmp_path, n_joints=4)) as bus:
        port, ph = _dxl(bus, 2.0)
        found, comm = ph.broadcastPing(port)
        assert comm == dxl.COMM_SUCCESS and sorted(found) == [1, 2, 3, 4] and found[1][0] == 1060
        gsw = dxl.GroupSyncWrite(port, ph, 116, 4)
        goals = {1: 1900, 2: 2000, 3: 2100, 4: 2200}
        for i, g in goals.items():
            gsw.addParam(i, list(g.to_bytes(4, "little")))
        assert gsw.txPacket() == dxl.COMM_SUCCESS
        gsr = dxl.GroupSyncRead(port, ph, 116, 4)
        for i in goals:
            gsr.addParam(i)
        assert gsr.txRxPacket() == dxl.COMM_SUCCESS
        assert {i: gsr.getData(i, 116, 4) for i in goals} == goals
        assert gsr.fastSyncRead() == dxl.COMM_SUCCESS
        assert {i: gsr.getData(i, 116, 4) for i in goals} == goals
        # reg write is held until ACTION
        ph.regWriteTxRx(port, 1, 65, 1, [1])
        assert ph.read1ByteTxRx(port, 1, 65)[0] == 0
        ph.action(port, dxl.BROADCAST_ID)
        time.sleep(0.02)
        assert ph.read1ByteTxRx(port, 1, 65)[0] == 1
        port.closePort()


def test_back_to_back_packets_all_served(tmp_path):
    with VirtualBus(make_robot(tmp_path)) as bus:
        ser = serial.Serial(bus.port, 1_000_000, timeout=0.3)
        ph = dxl.PacketHandler(2.0)
        pkts = b""
        for sid in (1, 2, 3):
            tx = [0] * 10
            tx[4], tx[5], tx[6], tx[7] = sid, 3, 0, 1
            tx[:4] = [0xFF, 0xFF, 0xFD, 0x00]
            crc = ph.updateCRC(0, tx, 8)
            tx[8], tx[9] = crc & 0xFF, crc >> 8
            pkts += bytes(tx)
        ser.write(pkts)  # three pings in one write
        time.sleep(0.1)
        replies = Parser2().feed(ser.read(4096))
        ser.close()
    assert [p.servo_id for p in replies] == [1, 2, 3]


def test_wrong_baud_gets_no_answer(tmp_path):
    with VirtualBus(make_robot(tmp_path, baudrate=57600)) as bus:
        port, ph = _dxl(bus, 2.0, baud=1_000_000)
        assert ph.ping(port, 1)[1] == dxl.COMM_RX_TIMEOUT
        port.setBaudRate(57600)
        assert ph.ping(port, 1)[0] == 1060
        port.closePort()


def test_p1_ax12_ping_read_write_sync_write(tmp_path):
    with VirtualBus(make_robot(tmp_path, family="dynamixel", protocol=1.0)) as bus:
        port, ph = _dxl(bus, 1.0)
        assert ph.ping(port, 2)[:2] == (12, dxl.COMM_SUCCESS)
        assert ph.write2ByteTxRx(port, 1, 36, 5) == (dxl.COMM_SUCCESS, 0x40)  # read-only: instruction error
        ph.write1ByteTxRx(port, 1, 47, 1)  # Lock
        assert ph.write1ByteTxRx(port, 1, 11, 60)[1] == 0x40  # EEPROM locked
        gsw = dxl.GroupSyncWrite(port, ph, 30, 2)
        for i, g in ((1, 400), (2, 500), (3, 600)):
            gsw.addParam(i, [g & 0xFF, g >> 8])
        assert gsw.txPacket() == dxl.COMM_SUCCESS
        assert [ph.read2ByteTxRx(port, i, 30)[0] for i in (1, 2, 3)] == [400, 500, 600]
        port.closePort()


def test_sts3215_ping_read_write_sync(tmp_path, scs_end):
    with VirtualBus(make_robot(tmp_path, family="feetech", protocol=0)) as bus:
        port = scs.PortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph = scs.PacketHandler(0)
        assert ph.ping(port, 1) == (777, scs.COMM_SUCCESS, 0)
        assert ph.read1ByteTxRx(port, 1, 62)[0] == 74  # 7.4 V
        assert ph.write2ByteTxRx(port, 1, 56, 5) == (scs.COMM_SUCCESS, 0x40)  # read-only
        gsw = scs.GroupSyncWrite(port, ph, 42, 2)
        for i, g in ((1, 1500), (2, 2500), (3, 3000)):
            gsw.addParam(i, [scs.SCS_LOBYTE(g), scs.SCS_HIBYTE(g)])
        assert gsw.txPacket() == scs.COMM_SUCCESS
        gsr = scs.GroupSyncRead(port, ph, 42, 2)
        for i in (1, 2, 3):
            gsr.addParam(i)
        assert gsr.txRxPacket() == scs.COMM_SUCCESS
        assert [gsr.getData(i, 42, 2) for i in (1, 2, 3)] == [1500, 2500, 3000]
        # sign-magnitude: a negative present velocity while moving down
        ph.write1ByteTxRx(port, 3, 40, 1)
        ph.write2ByteTxRx(port, 3, 42, 1000)
        time.sleep(0.05)
        raw = ph.read2ByteTxRx(port, 3, 58)[0]
        assert raw & 0x8000 and scs.SCS_TOHOST(raw, 15) < 0
        port.closePort()


def test_scs_big_endian(tmp_path, scs_end):
    with VirtualBus(make_robot(tmp_path, family="feetech", protocol=1)) as bus:
        port = scs.PortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph = scs.PacketHandler(1)
        assert ph.ping(port, 1)[0] == 1284
        raw = bytes(ph.readTxRx(port, 1, 3, 2)[0])
        assert raw == (1284).to_bytes(2, "big")
        port.closePort()


def test_fault_spec_grammar():
    f = FaultSpec.parse("noreply=0.05,badcrc=0.02,delay=0.01:0.05,hwerror=3:overload@2.0,vanish=5@3.0,disconnect@4.0")
    assert (f.noreply, f.badcrc, f.delay_min_s, f.delay_max_s, f.delay_p) == (0.05, 0.02, 0.01, 0.05, 1.0)
    assert f.hwerrors == [(3, ("overload",), 2.0)] and f.vanish == [(5, 3.0)] and f.disconnect_at_s == 4.0
    for bad in ("noreply=2", "hwerror=3:melting@1", "bogus=1", "vanish=x@1", "delay=0.5:0.1", "torqueoff=some@1"):
        with pytest.raises(InputError, match="noreply=P"):
            FaultSpec.parse(bad)
    f = FaultSpec.parse("torqueoff=2@1.5,torqueoff=all@3,reboot=4@2")
    assert f.torqueoff == [(2, 1.5), (None, 3.0)] and f.reboot == [(4, 2.0)]
    assert str(f) == "torqueoff=2@1.5,torqueoff=all@3.0,reboot=4@2.0"


def test_timed_torque_off_and_reboot_leave_the_servo_limp_and_answering(tmp_path):
    """A second program switching torque off, and a brownout (reboot: RAM back to defaults), as timed faults."""
    with VirtualBus(make_robot(tmp_path), "torqueoff=all@0.5,reboot=2@0.5") as bus:
        port, ph = _dxl(bus, 2.0)
        for sid in (1, 2, 3):
            ph.write4ByteTxRx(port, sid, 112, 100)  # Profile Velocity (RAM)
            ph.write1ByteTxRx(port, sid, 64, 1)
        assert all(s.torque_on for s in bus.servos)
        while bus.elapsed_s < 0.6:
            time.sleep(0.01)
        assert [ph.read1ByteTxRx(port, sid, 64)[:2] for sid in (1, 2, 3)] == [(0, dxl.COMM_SUCCESS)] * 3
        assert [ph.read4ByteTxRx(port, sid, 112)[0] for sid in (1, 2, 3)] == [100, 0, 100]
        port.closePort()
    assert sum("switched off" in e for e in bus.errors) == 3 and any("rebooted" in e for e in bus.errors)


def test_injected_hw_error_sets_alert_and_drops_torque(tmp_path):
    with VirtualBus(make_robot(tmp_path), "hwerror=2:overload@0") as bus:
        port, ph = _dxl(bus, 2.0)
        time.sleep(0.02)
        _, comm, err = ph.read4ByteTxRx(port, 2, 132)
        assert comm == dxl.COMM_SUCCESS and err & 0x80
        assert ph.read1ByteTxRx(port, 2, 70)[0] == 0x20
        ph.write1ByteTxRx(port, 2, 64, 1)
        assert ph.read1ByteTxRx(port, 2, 64)[0] == 0  # cannot re-enable torque while in overload
        ph.reboot(port, 2)
        assert ph.read1ByteTxRx(port, 2, 70)[0] == 0
        port.closePort()


def test_disconnect_gives_clients_io_errors(tmp_path):
    with VirtualBus(make_robot(tmp_path), "disconnect@0.1") as bus:
        ser = serial.Serial(bus.port, 1_000_000, timeout=0.05)
        time.sleep(0.3)
        with pytest.raises((serial.SerialException, OSError)):
            ser.write(b"\xff\xff\xfd\x00\x01\x03\x00\x01\x19\x4e")
            ser.read(10)
        assert any("disconnected" in e for e in bus.errors)


def test_record_shapes_and_atomic_save(tmp_path):
    robot = make_robot(tmp_path)
    before = time.monotonic()
    with VirtualBus(robot) as bus:
        time.sleep(0.1)
        out = bus.save_record(tmp_path / "rec" / "bus.npz")
        after = time.monotonic()
    with np.load(out) as z:
        # the bus clock's zero on time.monotonic(): samples line up with a client's own stamps
        assert before <= float(z["t0_monotonic_s"]) <= after
        assert before <= float(z["t0_monotonic_s"]) + z["t_s"][-1] <= after
        n, s = z["goal_ticks"].shape
        assert n >= 5 and s == 3
        assert z["present_ticks"].shape == z["torque_on"].shape == (n, s) and z["torque_on"].dtype == bool
        assert list(z["servo_ids"]) == [1, 2, 3]
        assert np.all(z["min_ticks"] < z["max_ticks"])
        assert np.all(np.diff(z["t_s"]) > 0)
    assert not list((tmp_path / "rec").glob("*.tmp"))
