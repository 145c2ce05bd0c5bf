"""Dynamixel backend on the ROBOTIS ``dynamixel_sdk``: Protocol 2.0 (X-series) and 1.0 (AX/MX).

Quirks kept here: the Protocol 2.0 status layout (CRC-16, error byte with the hardware-alert bit),
sign conventions per protocol, and Protocol 1.0 having no sync read (positions are read servo by servo).
"""

from __future__ import annotations

import math
from enum import Enum
from typing import Any

import dynamixel_sdk as dxl

from robogest.backends.base import register_backend
from robogest.backends.dynamixel_tables import (
    MODELS,
    P1_ERRORS,
    P1_SIGN_BITS,
    X_HW_ERRORS,
    X_SIGNED,
    X_STATUS_ERRORS,
    P1Reg,
    XReg,
)
from robogest.backends.servo_common import ServoBackend, ServoModel, describe_bits, sign_magnitude_decode
from robogest.errors import BackendError, ConfigError
from robogest.robot.config import RobotConfig

#: X-series models whose address 126 is Present Current (mA units), not Present Load (0.1 %).
CURRENT_SENSING = frozenset({"XM430-W350", "XL330-M288"})
#: X-series Operating Mode values in which Goal Position is an angle: position, extended position, current-based.
POSITION_MODES = frozenset({3, 4, 5})
#: Protocol 2.0 status packet: id at 4, error byte at 8, parameters from 9, two CRC bytes (dynamixel_sdk PKT_*).
P2_STATUS_LAYOUT = (4, 8, 9, 2)


def _to_signed(v: int, size: int) -> int:
    return v - (1 << (8 * size)) if v & (1 << (8 * size - 1)) else v


@register_backend("dynamixel")
class DynamixelBackend(ServoBackend):
    family = "dynamixel"
    sdk = dxl

    def __init__(self, robot: RobotConfig, port: str | None = None, baudrate: int | None = None, **options: Any):
        super().__init__(robot, port, baudrate, **options)
        p2 = self.protocol == 2.0
        R = XReg if p2 else P1Reg
        if p2:
            self.STATUS_LAYOUT = P2_STATUS_LAYOUT
        self.REG = {
            "model": R.MODEL_NUMBER,
            "goal": R.GOAL_POSITION,
            "present": R.PRESENT_POSITION,
            "torque": R.TORQUE_ENABLE,
            "temperature": R.PRESENT_TEMPERATURE,
            "voltage": XReg.PRESENT_INPUT_VOLTAGE if p2 else P1Reg.PRESENT_VOLTAGE,
            "load": R.PRESENT_LOAD,
            "min": XReg.MIN_POSITION_LIMIT if p2 else P1Reg.CW_ANGLE_LIMIT,
            "max": XReg.MAX_POSITION_LIMIT if p2 else P1Reg.CCW_ANGLE_LIMIT,
            "speed_cap": XReg.PROFILE_VELOCITY if p2 else P1Reg.MOVING_SPEED,
            "acceleration": XReg.PROFILE_ACCELERATION if p2 else P1Reg.GOAL_ACCELERATION,  # not on AX-12A
        }

    @classmethod
    def lookup_model(cls, name: str, protocol: float) -> ServoModel:
        key = name.upper().replace("_", "-")
        m = next((m for n, m in MODELS.items() if n == key or n.startswith(key)), None)
        if m is None:
            raise ConfigError(f"unknown Dynamixel model {name!r}; known: {', '.join(MODELS)}")
        if m.protocol != protocol:
            raise ConfigError(f"{m.name} speaks Protocol {m.protocol}, bus says {protocol}")
        return ServoModel(m.name, m.number, m.ticks_per_rev, m.centre_tick, m.max_tick,
                          m.speed_unit_rpm * 2 * math.pi / 60, m.speed_max_units,
                          m.accel_unit_rad_s2, m.accel_max_units)  # fmt: skip

    def _packet_protocol(self) -> float:
        return self.protocol

    def _decode(self, reg: Enum, raw: int) -> int:
        if reg in X_SIGNED:
            return _to_signed(raw, reg.value[1])
        return sign_magnitude_decode(raw, P1_SIGN_BITS.get(reg))  # type: ignore[call-overload]

    def _load_is_percent(self, k: int) -> bool:
        return k < 0 or self.models[k].name not in CURRENT_SENSING  # these report current at address 126

    def _has_sync_read(self) -> bool:
        return self.protocol == 2.0  # Protocol 1.0 has no SYNC READ: one read per servo

    def _rx_packet(self) -> tuple[list[int], bool]:
        if self.protocol != 2.0:
            return super()._rx_packet()
        pkt, comm = self._ph.rxPacket(self._port, False)
        return list(pkt), comm == dxl.COMM_SUCCESS

    def _hardware_error(self, sid: int, err: int) -> str | None:
        if not err:
            return None
        if self.protocol != 2.0:
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
        if self.protocol != 2.0:
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
        p2 = self.protocol == 2.0
        lo = self.read_register(sid, XReg.MIN_VOLTAGE_LIMIT if p2 else P1Reg.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, XReg.MAX_VOLTAGE_LIMIT if p2 else P1Reg.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
