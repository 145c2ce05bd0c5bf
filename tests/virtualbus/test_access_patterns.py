"""The simulated bus answers the access patterns of client libraries other than our backends: LeRobot-style
write-then-read of single registers, bulk transfers, broadcast ping in raw frames, EEPROM writes under Lock,
and return-delay time on the reply timing."""

from __future__ import annotations

import time

import dynamixel_sdk as dxl
import pytest
import scservo_sdk as scs
import serial

from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot


@pytest.fixture(autouse=True)
def _scs_end():
    yield
    scs.SCS_SETEND(0)


def _open(sdk, bus: VirtualBus, baud: int = 1_000_000):
    port = sdk.PortHandler(bus.port)
    assert port.openPort() and port.setBaudRate(baud)
    return port


def test_sts3215_accepts_lerobot_configure_motors_writes(tmp_path):
    """LeRobot's Feetech configure_motors(): Return_Delay_Time 0, Maximum_Acceleration 254 (address 85),
    Acceleration 254; each written then read back on its own."""
    with VirtualBus(make_robot(tmp_path, family="feetech", protocol=0, n_joints=2)) as bus:
        port, ph = _open(scs, bus), scs.PacketHandler(0)
        for sid in (1, 2):
            for addr, value in ((55, 0), (7, 0), (85, 254), (41, 254), (84, 200), (55, 1)):
                assert ph.write1ByteTxRx(port, sid, addr, value) == (scs.COMM_SUCCESS, 0), addr
                assert ph.read1ByteTxRx(port, sid, addr) == (value, scs.COMM_SUCCESS, 0), addr
        assert ph.write1ByteTxRx(port, 1, 50, 1)[1] == 0x40  # a reserved address is still refused
        port.closePort()


def test_feetech_lock_decides_what_survives_a_power_cycle(tmp_path):
    with VirtualBus(make_robot(tmp_path, family="feetech", protocol=0, n_joints=1)) as bus:
        port, ph = _open(scs, bus), scs.PacketHandler(0)
        servo = bus.servo(1)
        assert ph.write1ByteTxRx(port, 1, 55, 1) == (scs.COMM_SUCCESS, 0)  # locked
        assert ph.write2ByteTxRx(port, 1, 11, 3000) == (scs.COMM_SUCCESS, 0)  # applied, not saved
        assert ph.read2ByteTxRx(port, 1, 11)[0] == 3000
        with bus._lock:
            servo.power_cycle()
        assert ph.read2ByteTxRx(port, 1, 11)[0] == 4095
        assert ph.write1ByteTxRx(port, 1, 55, 0) == (scs.COMM_SUCCESS, 0)  # unlocked: saved
        assert ph.write2ByteTxRx(port, 1, 11, 3100) == (scs.COMM_SUCCESS, 0)
        with bus._lock:
            servo.power_cycle()
        assert ph.read2ByteTxRx(port, 1, 11)[0] == 3100
        port.closePort()


def test_ax12_lock_leaves_only_24_to_35_writable_until_power_off(tmp_path):
    with VirtualBus(make_robot(tmp_path, family="dynamixel", protocol=1.0, n_joints=1)) as bus:
        port, ph = _open(dxl, bus), dxl.PacketHandler(1.0)
        assert ph.write1ByteTxRx(port, 1, 47, 1) == (dxl.COMM_SUCCESS, 0)
        assert ph.write2ByteTxRx(port, 1, 30, 600) == (dxl.COMM_SUCCESS, 0)  # goal: allowed
        assert ph.write2ByteTxRx(port, 1, 48, 40)[1] == 0x40  # Punch: refused
        assert ph.write1ByteTxRx(port, 1, 47, 0)[1] == 0x40  # cannot unlock
        with bus._lock:
            bus.servo(1).power_cycle()
        assert ph.read1ByteTxRx(port, 1, 47)[0] == 0
        assert ph.write2ByteTxRx(port, 1, 48, 40) == (dxl.COMM_SUCCESS, 0)
        port.closePort()


def test_x_series_eeprom_write_then_read_with_torque_off(tmp_path):
    """LeRobot's Dynamixel configure_motors() writes Return_Delay_Time 0 and reads it back."""
    with VirtualBus(make_robot(tmp_path, n_joints=3), return_delay_time=None) as bus:  # factory: 250
        port, ph = _open(dxl, bus), dxl.PacketHandler(2.0)
        for sid in (1, 2, 3):
            assert ph.read1ByteTxRx(port, sid, 9)[0] == 250
            assert ph.write1ByteTxRx(port, sid, 9, 0) == (dxl.COMM_SUCCESS, 0)
            assert ph.read1ByteTxRx(port, sid, 9) == (0, dxl.COMM_SUCCESS, 0)
            assert ph.write1ByteTxRx(port, sid, 11, 4) == (dxl.COMM_SUCCESS, 0)  # extended position mode
            assert ph.read1ByteTxRx(port, sid, 11)[0] == 4
            assert ph.write1ByteTxRx(port, sid, 11, 5) == (dxl.COMM_SUCCESS, 0x04)  # no current mode on an XL430
        port.closePort()


def test_p2_bulk_read_and_bulk_write(tmp_path):
    with VirtualBus(make_robot(tmp_path, n_joints=3)) as bus:
        port, ph = _open(dxl, bus), dxl.PacketHandler(2.0)
        bw = dxl.GroupBulkWrite(port, ph)
        assert bw.addParam(1, 65, 1, [1])  # LED
        assert bw.addParam(2, 112, 4, list((321).to_bytes(4, "little")))  # Profile Velocity
        assert bw.txPacket() == dxl.COMM_SUCCESS
        br = dxl.GroupBulkRead(port, ph)
        assert br.addParam(1, 65, 1) and br.addParam(2, 112, 4) and br.addParam(3, 146, 1)
        assert br.txRxPacket() == dxl.COMM_SUCCESS
        assert br.getData(1, 65, 1) == 1 and br.getData(2, 112, 4) == 321
        assert 25 <= br.getData(3, 146, 1) <= 40  # temperature
        port.closePort()


def test_p1_bulk_read(tmp_path):
    """MX-28 BULK_READ (0x92). dynamixel_sdk 4.1's GroupBulkRead cannot send it on Protocol 1.0 (passes an
    extra argument), so the packet handler's bulkReadTx is called directly."""
    with VirtualBus(make_robot(tmp_path, family="dynamixel", protocol=1.0, model="MX-28", n_joints=3)) as bus:
        port, ph = _open(dxl, bus), dxl.PacketHandler(1.0)
        assert ph.bulkReadTx(port, [2, 1, 36, 1, 3, 43], 6) == dxl.COMM_SUCCESS  # (length, id, address) each
        first, comm1 = ph.rxPacket(port)
        port.setPacketTimeout(8)
        second, comm2 = ph.rxPacket(port)
        assert comm1 == comm2 == dxl.COMM_SUCCESS
        assert first[2] == 1 and abs((first[5] | first[6] << 8) - bus.servo(1).get("present")) <= 2
        assert second[2] == 3 and second[5] == bus.servo(3).get("temperature")
        port.closePort()


def _raw_replies(bus: VirtualBus, frame: bytes, n: int, timeout_s: float = 1.0) -> bytes:
    with serial.Serial(bus.port, 1_000_000, timeout=0) as ser:
        ser.write(frame)
        data = b""
        t_end = time.monotonic() + timeout_s
        while len(data) < n and time.monotonic() < t_end:
            data += ser.read(256)
            time.sleep(0.002)
        return data


@pytest.mark.parametrize(("family", "protocol"), [("feetech", 0.0), ("dynamixel", 1.0)])
def test_broadcast_ping_in_raw_frames_answers_every_servo_in_id_order(tmp_path, family, protocol):
    """scservo_sdk has no broadcast ping; a client library that sends FF FF FE 02 01 FE gets one
    6-byte status packet per servo."""
    with VirtualBus(make_robot(tmp_path, family=family, protocol=protocol, n_joints=3, ids=[7, 3, 5])) as bus:
        frame = bytes([0xFF, 0xFF, 0xFE, 0x02, 0x01, (~(0xFE + 0x02 + 0x01)) & 0xFF])
        data = _raw_replies(bus, frame, 18)
    packets = [data[k : k + 6] for k in range(0, len(data), 6)]
    assert [p[2] for p in packets] == [3, 5, 7]
    assert all(p[:2] == b"\xff\xff" and p[3] == 2 and p[5] == (~(p[2] + 2 + p[4])) & 0xFF for p in packets)


def test_return_delay_time_delays_each_reply_of_a_sync_read(tmp_path):
    """Replies of a sync read follow one another, each after its servo's Return Delay Time (2 us units)."""
    robot = make_robot(tmp_path, family="feetech", protocol=0, n_joints=6)
    with VirtualBus(robot) as bus:
        port, ph = _open(scs, bus), scs.PacketHandler(0)
        for sid in range(1, 7):
            assert ph.write1ByteTxRx(port, sid, 7, 254) == (scs.COMM_SUCCESS, 0)  # 508 us each
        assert all(abs(s.return_delay_s - 508e-6) < 1e-9 for s in bus.servos)
        gsr = scs.GroupSyncRead(port, ph, 56, 2)
        for sid in range(1, 7):
            gsr.addParam(sid)
        t0 = time.monotonic()
        assert gsr.txRxPacket() == scs.COMM_SUCCESS
        assert time.monotonic() - t0 >= 6 * 508e-6  # a lower bound: load can only make it slower
        port.closePort()
