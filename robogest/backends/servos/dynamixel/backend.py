"""Dynamixel backend on the ROBOTIS ``dynamixel_sdk``: Protocol 2.0 (X-series) and 1.0 (AX/MX).

Quirks kept here: the hardware-alert bit of Protocol 2.0's error byte (its detail is a register), the Operating and
Drive Mode checks, current-sensing models, and the voltage-limit registers. The wire (status layout, CRC, signs,
Protocol 1.0 having no sync read) is this folder's :class:`~robogest.backends.servos.wire.Wire`.
"""

from __future__ import annotations

from robogest.backends.base import register_backend
from robogest.backends.servos.bus import ServoBackend
from robogest.backends.servos.dynamixel.tables import (
    MODELS,
    P1_ERRORS,
    X_HW_ERRORS,
    X_STATUS_ERRORS,
    P1Reg,
    XReg,
)
from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.wire import describe_bits
from robogest.errors import BackendError, ConfigError

#: X-series models whose address 126 is Present Current (mA units), not Present Load (0.1 %).
CURRENT_SENSING = frozenset({"XM430-W350", "XL330-M288"})
#: X-series Operating Mode values in which Goal Position is an angle: position, extended position, current-based.
POSITION_MODES = frozenset({3, 4, 5})


@register_backend("dynamixel")
class DynamixelBackend(ServoBackend):
    family = "dynamixel"

    @property
    def _p2(self) -> bool:
        return self.protocol is ServoProtocol.DXL2

    @classmethod
    def lookup_model(cls, name: str, protocol: ServoProtocol | float) -> ServoModel:
        protocol = cls._protocol_of(protocol)
        key = name.upper().replace("_", "-")
        m = next((m for n, m in MODELS.items() if n == key or n.startswith(key)), None)
        if m is None:
            raise ConfigError(f"unknown Dynamixel model {name!r}; known: {', '.join(MODELS)}")
        if m.protocol is not protocol:
            raise ConfigError(f"{m.name} speaks Protocol {m.protocol.number}, bus says {protocol.number}")
        return m

    def _load_is_percent(self, k: int) -> bool:
        return k < 0 or self.models[k].name not in CURRENT_SENSING  # these report current at address 126

    def _hardware_error(self, sid: int, err: int) -> str | None:
        if not err:
            return None
        if not self._p2:
            return describe_bits(err, P1_ERRORS)
        parts = []
        if err & 0x80:
            status, ok, _, _ = self._read_raw(sid, XReg.HARDWARE_ERROR_STATUS)
            detail = describe_bits(status, X_HW_ERRORS) if ok else "unreadable Hardware Error Status"
            parts.append(f"hardware error: {detail}")
        if err & 0x7F:
            parts.append(X_STATUS_ERRORS.get(err & 0x7F, f"status error {err & 0x7F}"))
        return "; ".join(parts)

    def _check_position_mode(self, sid: int) -> None:
        if not self._p2:
            return  # AX/MX: wheel mode is both angle limits at 0, checked with the limits
        mode = self.read_register(sid, XReg.OPERATING_MODE)
        if mode not in POSITION_MODES:
            raise BackendError(
                f"{self._who(sid)}: Operating Mode (register 11) is {mode}, not a position mode (3 position, 4 "
                "extended position, 5 current-based position); set it to 3 with torque off (Dynamixel Wizard)"
            )
        drive = self.read_register(sid, XReg.DRIVE_MODE)
        if drive & 0x05:
            why = "the reverse bit (0) reverses the servo" if drive & 0x01 else "bit 2 makes Profile Velocity a time"
            raise BackendError(
                f"{self._who(sid)}: Drive Mode (register 10) is {drive}: {why}; clear bits 0 and 2 (direction: -1 in "
                "the robot YAML mirrors a joint instead)"
            )

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        p2 = self._p2
        lo = self.read_register(sid, XReg.MIN_VOLTAGE_LIMIT if p2 else P1Reg.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, XReg.MAX_VOLTAGE_LIMIT if p2 else P1Reg.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
