"""Feetech backend on ``scservo_sdk``: STS/SMS (protocol 0, little-endian) and SCS (protocol 1, big-endian).

Quirks kept here: the Operating Mode check (STS) and the status error bits; the wire (byte order re-asserted before
every call, sign-magnitude positions and speeds) is this folder's :class:`~robogest.backends.servos.wire.Wire`.
"""

from __future__ import annotations

from robogest.backends.base import register_backend
from robogest.backends.servos.bus import ServoBackend
from robogest.backends.servos.feetech.tables import FT_ERRORS, MODELS, SCSReg, STSReg
from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.wire import describe_bits
from robogest.errors import BackendError, ConfigError


@register_backend("feetech")
class FeetechBackend(ServoBackend):
    family = "feetech"

    @property
    def _table(self) -> type[STSReg] | type[SCSReg]:
        return STSReg if self.protocol is ServoProtocol.STS else SCSReg

    @classmethod
    def lookup_model(cls, name: str, protocol: ServoProtocol | float) -> ServoModel:
        protocol = cls._protocol_of(protocol)
        key = name.upper().replace("-", "").replace("_", "")
        m = MODELS.get(key)
        if m is None:
            raise ConfigError(f"unknown Feetech model {name!r}; known: {', '.join(MODELS)}")
        if m.protocol is not protocol:
            raise ConfigError(f"{m.name} uses protocol {m.protocol.number:g}, bus says {protocol.number:g}")
        return m

    def _hardware_error(self, sid: int, err: int) -> str | None:
        return describe_bits(err, FT_ERRORS) if err else None

    def _check_position_mode(self, sid: int) -> None:
        if self.protocol is not ServoProtocol.STS:
            return  # SCS: wheel mode is both angle limits at 0, checked with the limits
        mode = self.read_register(sid, STSReg.OPERATING_MODE)
        if mode != 0:
            raise BackendError(
                f"{self._who(sid)}: Operating Mode (register 33) is {mode}, not 0 (position): in speed mode it "
                "would turn continuously; set it to 0 with torque off"
            )

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        R = self._table
        lo = self.read_register(sid, R.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, R.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
