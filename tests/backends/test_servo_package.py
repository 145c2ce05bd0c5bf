"""The servo package's shape: one protocol enum, one model record, one transport shared by the backends and bring-up,
and every family folder found and complete (a new family is one folder)."""

from __future__ import annotations

from pkgutil import iter_modules

import pytest

from robogest.backends import get_backend_factory, servos
from robogest.backends.servos.bus import ServoBackend
from robogest.backends.servos.protocol import PROTOCOL_NAMES, ServoModel, ServoProtocol
from robogest.backends.servos.transport import Transport
from robogest.backends.servos.wire import wire_of
from robogest.errors import BackendError
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot


def test_every_family_folder_is_a_registered_backend_with_a_wire_per_protocol():
    folders = {m.name for m in iter_modules(servos.__path__) if m.ispkg}
    assert folders == {p.family for p in ServoProtocol}
    for p in ServoProtocol:
        wire = wire_of(p)
        assert wire.protocol is p
        backend = get_backend_factory(p.family)
        assert issubclass(backend, ServoBackend) and backend.family == p.family
        mine = [m for m in wire.models.values() if m.protocol is p]
        assert mine, f"{p.describe()}: no model"
        for m in mine:  # one record type, found by the family's lookup under the YAML's protocol number too
            assert isinstance(m, ServoModel)
            assert backend.lookup_model(m.name, p) is m is backend.lookup_model(m.name, p.number)


def test_the_cli_offers_the_protocol_enum_names():
    from robogest.cli.servo_raw_cmds import PROTOCOL_CHOICES

    assert PROTOCOL_CHOICES == PROTOCOL_NAMES
    assert [ServoProtocol.named(n) for n in PROTOCOL_NAMES] == list(ServoProtocol)
    assert ServoProtocol.of_bus("feetech", 1) is ServoProtocol.SCS


@pytest.mark.parametrize(
    ("protocol", "register", "value", "raw"),
    [
        (ServoProtocol.STS, "GOAL_POSITION", -5, 0x8005),  # sign-magnitude, bit 15
        (ServoProtocol.STS, "PRESENT_LOAD", -3, 0x403),  # sign-magnitude, bit 10
        (ServoProtocol.DXL2, "PRESENT_POSITION", -5, 0xFFFFFFFB),  # two's complement, 4 bytes
        (ServoProtocol.DXL2, "PROFILE_VELOCITY", 70, 70),  # unsigned
    ],
)
def test_the_wire_signs_register_values_as_the_tables_say(protocol, register, value, raw):
    wire = wire_of(protocol)
    reg = wire.reg(register)
    assert wire.encode(reg, value) == raw and wire.decode(reg, raw) == value


def test_scs_values_are_big_endian_on_the_wire_and_sts_little():
    assert wire_of(ServoProtocol.SCS).to_bytes(0x1234, 2) == [0x12, 0x34]
    assert wire_of(ServoProtocol.STS).to_bytes(0x1234, 2) == [0x34, 0x12]
    assert wire_of(ServoProtocol.SCS).from_bytes([0x12, 0x34]) == 0x1234


@pytest.mark.parametrize(("family", "protocol"), [("dynamixel", 2.0), ("feetech", 1.0)])
def test_bring_up_reads_through_the_transport_and_names_servo_register_and_attempts(tmp_path, family, protocol):
    """The transport bring-up uses reads what the backend reads (the same byte order), and a servo that is not
    there gives one error naming the id, the register and how many attempts were made."""
    robot = make_robot(tmp_path, family=family, protocol=protocol, n_joints=2)
    proto = ServoProtocol.of_bus(family, protocol)
    with VirtualBus(robot) as bus:
        backend = get_backend_factory(family)(robot, port=bus.port)
        backend.connect()
        try:
            model = backend.read_register(1, backend.REG["model"])
            present = int(backend.rad_to_ticks(backend.read_positions())[0])
        finally:
            backend.shutdown()
        with Transport(bus.port, proto, robot.bus.baudrate) as link:
            assert link.read(1, link.wire.reg("MODEL_NUMBER")) == model == backend.models[0].number
            assert abs(link.read(1, link.wire.reg("PRESENT_POSITION")) - present) <= 2
            with pytest.raises(BackendError, match=r"servo id 9: reading MODEL_NUMBER: .* \(2 attempts\)"):
                link.read(9, link.wire.reg("MODEL_NUMBER"), attempts=2)
