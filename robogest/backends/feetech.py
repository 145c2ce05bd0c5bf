"""Feetech backend on ``scservo_sdk``: STS/SMS (protocol 0, little-endian) and SCS (protocol 1, big-endian).

Quirks kept here: the SDK keeps the byte order in a module-global (``SCS_SETEND``), so every call
re-asserts this bus's order; positions and speeds are sign-magnitude (bit 15) on STS.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import Any

import scservo_sdk as scs

from robogest.backends.base import register_backend
from robogest.backends.feetech_tables import FT_ERRORS, MODELS, SCS_SIGN_BITS, STS_SIGN_BITS, SCSReg, STSReg
from robogest.backends.servo_common import (
    ServoBackend,
    ServoModel,
    describe_bits,
    sign_magnitude_decode,
    sign_magnitude_encode,
)
from robogest.errors import BackendError, ConfigError
from robogest.robot.config import RobotConfig


@register_backend("feetech")
class FeetechBackend(ServoBackend):
    family = "feetech"
    sdk = scs

    def __init__(self, robot: RobotConfig, port: str | None = None, baudrate: int | None = None, **options: Any):
        super().__init__(robot, port, baudrate, **options)
        self._end = int(self.protocol)
        R = STSReg if self._end == 0 else SCSReg
        self._signs = STS_SIGN_BITS if self._end == 0 else SCS_SIGN_BITS
        self.REG = {
            "model": R.MODEL_NUMBER,
            "goal": R.GOAL_POSITION,
            "present": R.PRESENT_POSITION,
            "torque": R.TORQUE_ENABLE,
            "temperature": R.PRESENT_TEMPERATURE,
            "voltage": R.PRESENT_VOLTAGE,
            "load": R.PRESENT_LOAD,
            "min": R.MIN_POSITION_LIMIT,
            "max": R.MAX_POSITION_LIMIT,
            "speed_cap": R.GOAL_VELOCITY,
            "acceleration": R.ACCELERATION,  # written on STS only: SCS models have an accel unit of 0
        }
        self._R = R

    @classmethod
    def lookup_model(cls, name: str, protocol: float) -> ServoModel:
        key = name.upper().replace("-", "").replace("_", "")
        m = MODELS.get(key)
        if m is None:
            raise ConfigError(f"unknown Feetech model {name!r}; known: {', '.join(MODELS)}")
        if m.protocol_end != int(protocol):
            raise ConfigError(f"{m.name} uses protocol {m.protocol_end}, bus says {protocol:g}")
        step_rad = 2 * math.pi / m.ticks_per_rev
        return ServoModel(m.name, m.number, m.ticks_per_rev, m.centre_tick, m.max_tick, step_rad, m.speed_max_units,
                          m.accel_unit_steps_s2 * step_rad, m.accel_max_units)  # fmt: skip

    def _packet_protocol(self) -> int:
        return self._end

    def _to_bus_bytes(self, raw: int, size: int) -> list[int]:
        return list(raw.to_bytes(size, "big" if self._end else "little"))

    def _from_bus_bytes(self, data: bytes | list[int]) -> int:
        return int.from_bytes(bytes(data), "big" if self._end else "little")

    def _prep(self) -> None:
        scs.SCS_SETEND(self._end)  # the SDK's group writers encode with this module-global byte order
        self._port.is_using = False

    def _encode(self, reg: Enum, value: int) -> int:
        bit = self._signs.get(reg)  # type: ignore[call-overload]
        if bit is not None and value < 0:
            return sign_magnitude_encode(value, bit)
        return value & ((1 << (8 * reg.value[1])) - 1)

    def _decode(self, reg: Enum, raw: int) -> int:
        return sign_magnitude_decode(raw, self._signs.get(reg))  # type: ignore[call-overload]

    def _hardware_error(self, sid: int, err: int) -> str | None:
        return describe_bits(err, FT_ERRORS) if err else None

    def _check_position_mode(self, sid: int) -> None:
        if self._end != 0:
            return  # SCS: wheel mode is both angle limits at 0, checked with the limits
        mode = self.read_register(sid, STSReg.OPERATING_MODE)
        if mode != 0:
            raise BackendError(
                f"{self._who(sid)}: Operating Mode (register 33) is {mode}, not 0 (position): in speed mode it "
                "would turn continuously; set it to 0 with torque off"
            )

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        lo = self.read_register(sid, self._R.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, self._R.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
