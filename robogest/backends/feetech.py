"""Feetech backend on ``scservo_sdk``: STS/SMS (protocol 0, little-endian) and SCS (protocol 1, big-endian).

Quirks kept here: the SDK keeps the byte order in a module-global (``SCS_SETEND``), so every call
re-asserts this bus's order; positions and speeds are sign-magnitude (bit 15) on STS; sync reads use
the GroupSyncRead transmit, then match status packets to ids one by one (keeps each status error byte,
and a lost reply no longer swallows the ones after it as ``readRx`` does).
"""

from __future__ import annotations

from enum import Enum
from typing import Any

import scservo_sdk as scs

from robogest.backends.base import register_backend
from robogest.backends.feetech_tables import FT_ERRORS, MODELS, SCS_SIGN_BITS, STS_SIGN_BITS, SCSReg, STSReg
from robogest.backends.servo_common import (
    Raw,
    ServoBackend,
    ServoModel,
    collect_status_packets,
    describe_bits,
    sign_magnitude_decode,
)
from robogest.errors import ConfigError
from robogest.robot.config import RobotConfig

CRC_BYTES = 1  # checksum at the end of a status packet


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
            "goal": R.GOAL_POSITION,
            "present": R.PRESENT_POSITION,
            "torque": R.TORQUE_ENABLE,
            "temperature": R.PRESENT_TEMPERATURE,
            "voltage": R.PRESENT_VOLTAGE,
            "load": R.PRESENT_LOAD,
            "min": R.MIN_POSITION_LIMIT,
            "max": R.MAX_POSITION_LIMIT,
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
        return ServoModel(m.name, m.number, m.ticks_per_rev, m.centre_tick, m.max_tick)

    def _packet_protocol(self) -> int:
        return self._end

    def _sync_bytes(self, raw: int, size: int) -> list[int]:
        return [raw & 0xFF] if size == 1 else [scs.SCS_LOBYTE(raw), scs.SCS_HIBYTE(raw)]  # in the bus's byte order

    def _prep(self) -> None:
        scs.SCS_SETEND(self._end)
        self._port.is_using = False
        # scservo_sdk's clearPort() only drains output; bytes left by a corrupt or late reply would
        # otherwise be parsed as the answer to this transaction (dynamixel_sdk flushes input itself)
        self._port.ser.reset_input_buffer()

    def _encode(self, reg: Enum, value: int) -> int:
        bit = self._signs.get(reg)  # type: ignore[call-overload]
        if bit is not None and value < 0:
            return (-value & ((1 << bit) - 1)) | (1 << bit)
        return value & ((1 << (8 * reg.value[1])) - 1)

    def _decode(self, reg: Enum, raw: int) -> int:
        return sign_magnitude_decode(raw, self._signs.get(reg))  # type: ignore[call-overload]

    def _sync_read_raw(self, reg: Enum, ids: list[int]) -> dict[int, Raw]:
        self._prep()
        addr, size = reg.value
        group = scs.GroupSyncRead(self._port, self._ph, addr, size)
        for sid in ids:
            group.addParam(sid)
        comm = group.txPacket()
        if comm != scs.COMM_SUCCESS:
            return {sid: (0, False, 0, self._ph.getTxRxResult(comm)) for sid in ids}
        got = collect_status_packets(ids, self._rx_packet, self._port.isPacketTimeout, scs.PKT_ID)
        self._port.is_using = False
        p0 = scs.PKT_PARAMETER0
        out: dict[int, Raw] = {}
        for sid in ids:
            pkt = got[sid]
            if pkt is None or len(pkt) != p0 + size + CRC_BYTES:  # another length: a stale reply to another read
                out[sid] = (0, False, 0, "no valid status packet (missing or corrupt)")
                continue
            raw = pkt[p0] if size == 1 else scs.SCS_MAKEWORD(pkt[p0], pkt[p0 + 1])
            out[sid] = (self._decode(reg, raw), True, pkt[scs.PKT_ERROR], self._ph.getTxRxResult(scs.COMM_SUCCESS))
        return out

    def _rx_packet(self) -> tuple[list[int], bool]:
        pkt, comm = self._ph.rxPacket(self._port)
        return list(pkt), comm == scs.COMM_SUCCESS

    def _hardware_error(self, sid: int, err: int) -> str | None:
        return describe_bits(err, FT_ERRORS) if err else None

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        lo = self.read_register(sid, self._R.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, self._R.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
