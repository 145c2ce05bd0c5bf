"""The servo wire protocols robogest speaks, and the one record of a servo model.

A robot YAML names a bus by family and number (``family: feetech, protocol: 0``), the ``servo`` commands by name
(``--protocol sts``); both mean one :class:`ServoProtocol` member, and everything below the YAML and the command
line passes that member, never the number or the name.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from robogest.errors import InputError


class ServoProtocol(Enum):
    """One wire protocol: ``(name, family, number)``; ``number`` is ``bus.protocol`` in a robot YAML."""

    DXL2 = ("dxl2", "dynamixel", 2.0)  #: Dynamixel Protocol 2.0 (X series)
    STS = ("sts", "feetech", 0.0)  #: Feetech STS/SMS: Dynamixel 1.0 packets, little-endian values
    SCS = ("scs", "feetech", 1.0)  #: Feetech SCS: the same packets, big-endian values
    DXL1 = ("dxl1", "dynamixel", 1.0)  #: Dynamixel Protocol 1.0 (AX/MX): no sync read, no broadcast ping answers

    @property
    def cli_name(self) -> str:
        """What ``--protocol`` takes."""
        return self.value[0]

    @property
    def family(self) -> str:
        """The servo family (a backend name, and a folder of :mod:`robogest.backends.servos`)."""
        return self.value[1]

    @property
    def number(self) -> float:
        """``bus.protocol`` in a robot YAML."""
        return self.value[2]

    @property
    def byte_order(self) -> str:
        """Byte order of multi-byte register values on the wire: ``"big"`` on SCS only."""
        return "big" if self is ServoProtocol.SCS else "little"

    @property
    def has_sync_read(self) -> bool:
        return self is not ServoProtocol.DXL1

    def describe(self) -> str:
        """``"feetech protocol 0 (sts)"``: for messages."""
        return f"{self.family} protocol {self.number:g} ({self.cli_name})"

    @classmethod
    def named(cls, name: str) -> ServoProtocol:
        """The member ``--protocol name`` means; InputError naming the choices otherwise."""
        for p in cls:
            if p.cli_name == name:
                return p
        raise InputError(f"unknown servo protocol {name!r}; one of {', '.join(p.cli_name for p in cls)}")

    @classmethod
    def of_bus(cls, family: str, number: float) -> ServoProtocol:
        """The member a robot YAML's ``bus.family`` and ``bus.protocol`` mean."""
        for p in cls:
            if (p.family, p.number) == (family, float(number)):
                return p
        raise InputError(f"no servo protocol for family {family!r} protocol {number:g}")


#: ``--protocol`` names in the order a scan tries them: the most common first, Dynamixel 1.0 (no broadcast) last.
PROTOCOL_NAMES = tuple(p.cli_name for p in ServoProtocol)


@dataclass(frozen=True)
class ServoModel:
    """Facts about one servo model that the rad <-> tick mapping, the servos' own limits and ``connect`` need."""

    name: str
    #: What its Model Number register reads.
    number: int
    protocol: ServoProtocol
    ticks_per_rev: float
    centre_tick: int
    max_tick: int
    #: One unit of the servo's own speed-cap register (``REG["speed_cap"]``), rad/s at the servo horn.
    speed_unit_rad_s: float
    #: Largest value that register takes.
    speed_max_units: int
    #: One unit of the servo's own acceleration register (``REG["acceleration"]``), rad/s² at the servo horn; 0 for a
    #: model without one (AX-12A, SCS0009), whose acceleration limit is kept by the goal stream alone.
    accel_unit_rad_s2: float = 0.0
    #: Largest value that register takes.
    accel_max_units: int = 0
