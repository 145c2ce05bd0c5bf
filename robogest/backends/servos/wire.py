"""What the shared transport must know of one protocol, declared by its family's folder: the SDK, the packet
framing quirks, the control table and how register values are signed.

Each family package (``dynamixel/``, ``feetech/``) registers one :class:`Wire` per protocol it speaks;
:func:`wire_of` imports the family's folder on first use, so the SDK is loaded only when a port is opened.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from importlib import import_module

from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.sdk import SdkModule
from robogest.errors import ConfigError


class Register(Enum):
    """A control-table entry; its value is ``(address, size_bytes)``. A family's tables subclass this."""

    @property
    def addr(self) -> int:
        return int(self.value[0])

    @property
    def size(self) -> int:
        return int(self.value[1])


#: The register each role of a servo backend (:attr:`~.bus_io.ServoBusIO.REG`) uses: the first of these names the
#: protocol's table has (Dynamixel X, Dynamixel 1.0 and Feetech spell some differently).
ROLE_NAMES: dict[str, tuple[str, ...]] = {
    "model": ("MODEL_NUMBER",),
    "goal": ("GOAL_POSITION",),
    "present": ("PRESENT_POSITION",),
    "torque": ("TORQUE_ENABLE",),
    "temperature": ("PRESENT_TEMPERATURE",),
    "voltage": ("PRESENT_INPUT_VOLTAGE", "PRESENT_VOLTAGE"),
    "load": ("PRESENT_LOAD",),  # Present Current on current-sensing Dynamixel models (same address)
    "min": ("MIN_POSITION_LIMIT", "CW_ANGLE_LIMIT"),
    "max": ("MAX_POSITION_LIMIT", "CCW_ANGLE_LIMIT"),
    "speed_cap": ("PROFILE_VELOCITY", "MOVING_SPEED", "GOAL_VELOCITY"),
    "acceleration": ("PROFILE_ACCELERATION", "GOAL_ACCELERATION", "ACCELERATION"),  # none on AX-12A and SCS models
}

#: Where a status packet keeps the servo id, the error byte and the first parameter, and how many checksum bytes
#: end it.
StatusLayout = tuple[int, int, int, int]
#: Dynamixel Protocol 1.0 packets (Feetech's too): id at 2, error at 4, parameters from 5, one checksum byte.
P1_STATUS_LAYOUT: StatusLayout = (2, 4, 5, 1)


@dataclass(frozen=True)
class Wire:
    """One protocol as the transport drives it.

    ``load_sdk`` imports the vendor SDK; ``packet_arg`` is what its ``PacketHandler`` takes; ``rx_flags`` are passed
    to ``rxPacket`` (Dynamixel 2.0's fast-option flag); ``before_call`` runs before every transaction (Feetech keeps
    the byte order in a module global that each call must re-assert). ``registers`` is the control table, an Enum
    whose values are ``(address, size_bytes)``; ``sign_bits`` the registers stored sign-magnitude (register -> sign
    bit), ``twos_complement`` the ones stored as two's complement; ``models`` the family's servo models by name.
    """

    protocol: ServoProtocol
    load_sdk: Callable[[], SdkModule]
    packet_arg: float
    registers: type[Enum]
    models: Mapping[str, ServoModel]
    status_layout: StatusLayout = P1_STATUS_LAYOUT
    rx_flags: tuple[bool, ...] = ()
    before_call: Callable[[SdkModule], None] | None = None
    sign_bits: Mapping[Enum, int] = field(default_factory=dict)
    twos_complement: frozenset[Enum] = frozenset()

    def reg(self, *names: str) -> Enum:
        """The first of ``names`` this protocol's table has: callers name a register by its role across tables
        (``"MIN_POSITION_LIMIT", "CW_ANGLE_LIMIT"``); ConfigError when none is there."""
        members = self.registers.__members__
        for n in names:
            if n in members:
                reg: Enum = members[n]
                return reg
        raise ConfigError(f"{self.protocol.describe()} has no register {' or '.join(names)}")

    def roles(self) -> dict[str, Enum]:
        """The register of each role in :data:`ROLE_NAMES`."""
        return {role: self.reg(*names) for role, names in ROLE_NAMES.items()}

    def encode(self, reg: Enum, value: int) -> int:
        """Signed ``value`` -> the register's raw unsigned value (sign-magnitude where the table says so, else two's
        complement in the register's width)."""
        bit = self.sign_bits.get(reg)
        if bit is not None and value < 0:
            return sign_magnitude_encode(value, bit)
        size: int = reg.value[1]
        return value & ((1 << (8 * size)) - 1)

    def decode(self, reg: Enum, raw: int) -> int:
        """The register's raw unsigned value -> its signed value."""
        if reg in self.twos_complement:
            bits = 8 * reg.value[1]
            return raw - (1 << bits) if raw & (1 << (bits - 1)) else raw
        return sign_magnitude_decode(raw, self.sign_bits.get(reg))

    def to_bytes(self, raw: int, size: int) -> list[int]:
        """A raw register value as the bytes on the bus."""
        return list(raw.to_bytes(size, "big" if self.protocol.byte_order == "big" else "little"))

    def from_bytes(self, data: bytes | list[int]) -> int:
        """Bytes from the bus -> raw register value."""
        return int.from_bytes(bytes(data), "big" if self.protocol.byte_order == "big" else "little")

    def model_named(self, number: int) -> str:
        """The name of the family's model whose Model Number is ``number``; ``"?"`` when unknown."""
        return next((m.name for m in self.models.values() if m.number == number), "?")


_WIRES: dict[ServoProtocol, Wire] = {}


def register_wire(wire: Wire) -> None:
    """Called by a family package for each protocol it speaks."""
    _WIRES[wire.protocol] = wire


def wire_of(protocol: ServoProtocol) -> Wire:
    """The :class:`Wire` of ``protocol``, importing its family's folder on first use."""
    if protocol not in _WIRES:
        import_module(f"robogest.backends.servos.{protocol.family}")
    try:
        return _WIRES[protocol]
    except KeyError:
        raise ConfigError(f"no servo family package declares {protocol.describe()}") from None


def sign_magnitude_encode(value: int, bit: int) -> int:
    """``value`` as a register that stores the sign in bit ``bit`` and the magnitude below it."""
    return (-value & ((1 << bit) - 1)) | (1 << bit) if value < 0 else value


def sign_magnitude_decode(raw: int, bit: int | None) -> int:
    """Servo registers that store the sign in bit ``bit`` (Feetech positions/speeds, Dynamixel P1 load)."""
    if bit is not None and raw & (1 << bit):
        return -(raw & ((1 << bit) - 1))
    return raw


def describe_bits(err: int, table: Mapping[int, str]) -> str:
    """A status error byte as the names of its bits (``"overheating + overload error (0x24)"``)."""
    names = [name for bit, name in table.items() if err & bit]
    return " + ".join(names) + f" error (0x{err:02X})" if names else f"error 0x{err:02X}"
