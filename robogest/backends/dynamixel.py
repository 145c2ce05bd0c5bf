"""Dynamixel backend on the ROBOTIS ``dynamixel_sdk``: Protocol 2.0 (X-series) and 1.0 (AX/MX).

Quirks kept here: P2 sync reads go through the SDK's GroupSyncRead transmit, then status packets are
received one by one and matched to ids (the group API drops the status error byte and with it the
hardware-alert bit, and ``readRx`` discards every reply after a lost one);
Protocol 1.0 has no sync read, so positions are read servo by servo.
"""

from __future__ import annotations

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

P2_ID, P2_ERROR, P2_PARAMETER0 = 4, 8, 8  # byte offsets in a Protocol 2.0 status packet (dynamixel_sdk PKT_*)
CRC_BYTES = 2


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
        self.REG = {
            "goal": R.GOAL_POSITION,
            "present": R.PRESENT_POSITION,
            "torque": R.TORQUE_ENABLE,
            "temperature": R.PRESENT_TEMPERATURE,
            "voltage": XReg.PRESENT_INPUT_VOLTAGE if p2 else P1Reg.PRESENT_VOLTAGE,
            "load": R.PRESENT_LOAD,
            "min": XReg.MIN_POSITION_LIMIT if p2 else P1Reg.CW_ANGLE_LIMIT,
            "max": XReg.MAX_POSITION_LIMIT if p2 else P1Reg.CCW_ANGLE_LIMIT,
        }

    @classmethod
    def lookup_model(cls, name: str, protocol: float) -> ServoModel:
        key = name.upper().replace("_", "-")
        m = next((m for n, m in MODELS.items() if n == key or n.startswith(key)), None)
        if m is None:
            raise ConfigError(f"unknown Dynamixel model {name!r}; known: {', '.join(MODELS)}")
        if m.protocol != protocol:
            raise ConfigError(f"{m.name} speaks Protocol {m.protocol}, bus says {protocol}")
        return ServoModel(m.name, m.number, m.ticks_per_rev, m.centre_tick, m.max_tick)

    def _packet_protocol(self) -> float:
        return self.protocol

    def _decode(self, reg: Enum, raw: int) -> int:
        if reg in X_SIGNED:
            return _to_signed(raw, reg.value[1])
        return sign_magnitude_decode(raw, P1_SIGN_BITS.get(reg))  # type: ignore[call-overload]

    def _sync_read_raw(self, reg: Enum, ids: list[int]) -> dict[int, Raw]:
        if self.protocol != 2.0:
            return super()._sync_read_raw(reg, ids)
        self._port.is_using = False
        addr, size = reg.value
        group = dxl.GroupSyncRead(self._port, self._ph, addr, size)
        for sid in ids:
            group.addParam(sid)
        comm = group.txPacket()
        if comm != dxl.COMM_SUCCESS:
            return {sid: (0, False, 0, self._ph.getTxRxResult(comm)) for sid in ids}
        p0 = P2_PARAMETER0 + 1  # status packets carry the error byte before the data
        got = collect_status_packets(
            ids,
            self._rx_packet,
            self._port.isPacketTimeout,
            P2_ID,
        )
        self._port.is_using = False
        out: dict[int, Raw] = {}
        for sid in ids:
            pkt = got[sid]
            if pkt is None or len(pkt) != p0 + size + CRC_BYTES:  # another length: a stale reply to another read
                out[sid] = (0, False, 0, "no valid status packet (missing or corrupt)")
                continue
            raw = int.from_bytes(bytes(pkt[p0 : p0 + size]), "little")
            out[sid] = (self._decode(reg, raw), True, pkt[P2_ERROR], self._ph.getTxRxResult(dxl.COMM_SUCCESS))
        return out

    def _rx_packet(self) -> tuple[list[int], bool]:
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

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        p2 = self.protocol == 2.0
        lo = self.read_register(sid, XReg.MIN_VOLTAGE_LIMIT if p2 else P1Reg.MIN_VOLTAGE_LIMIT) / 10.0
        hi = self.read_register(sid, XReg.MAX_VOLTAGE_LIMIT if p2 else P1Reg.MAX_VOLTAGE_LIMIT) / 10.0
        return lo, hi
