"""How the simulated bus answers instruction packets: one dispatch table per protocol (instruction byte -> handler).

Two tables per protocol: *bus* instructions that address several servos in one packet (sync/bulk read and write,
broadcast ping) and *servo* instructions that every addressed servo executes alone (read, write, reg-write, action,
...), each answering with its own status packet unless broadcast. An instruction missing from both tables is
answered with the protocol's instruction error, as real servos do.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from robogest.virtualbus import framing
from robogest.virtualbus.servo import ERR_ACCESS, ERR_LENGTH, ERR_RANGE, SimServo

if TYPE_CHECKING:
    from robogest.virtualbus.bus import VirtualBus

BROADCAST = 0xFE
# instruction codes (shared numbering across protocols where they exist)
PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ, BULK_READ, BULK_WRITE = 0x82, 0x83, 0x8A, 0x92, 0x93
INST_NAMES = {
    PING: "PING", READ: "READ", WRITE: "WRITE", REG_WRITE: "REG_WRITE", ACTION: "ACTION", REBOOT: "REBOOT",
    FACTORY_RESET: "FACTORY_RESET", CLEAR: "CLEAR", SYNC_READ: "SYNC_READ", SYNC_WRITE: "SYNC_WRITE",
    FAST_SYNC_READ: "FAST_SYNC_READ", BULK_READ: "BULK_READ", BULK_WRITE: "BULK_WRITE",
}  # fmt: skip

# Protocol 2.0 status error codes (low 7 bits) and alert bit; Protocol 1.0 / Feetech bits.
P2_ERR = {ERR_ACCESS: 0x07, ERR_RANGE: 0x04, ERR_LENGTH: 0x05}
P2_INSTRUCTION_ERROR, P2_CRC_ERROR, P2_ALERT = 0x02, 0x03, 0x80
P1_ERR = {ERR_ACCESS: 0x40, ERR_RANGE: 0x08, ERR_LENGTH: 0x08}
P1_CHECKSUM_ERROR, P1_INSTRUCTION_ERROR = 0x10, 0x40

#: A bus instruction's handler: True when it dealt with the packet, False to treat it as a servo instruction
#: (a malformed or, for this family, unknown multi-servo instruction: answered with the instruction error).
BusHandler = Callable[[framing.Packet], bool]
#: A servo instruction's handler on one servo and the packet's parameters: ``(error code, data)`` of its status
#: packet, or None where the instruction never answers (Protocol 1.0 ACTION).
ServoHandler = Callable[[SimServo, bytes], tuple[int, bytes] | None]


def name_of(inst: int) -> str:
    """The instruction's name for the bus's notes (hex when unknown)."""
    return INST_NAMES.get(inst, hex(inst))


def crc16_bytes(data: bytes | bytearray) -> bytes:
    return framing.crc16(data).to_bytes(2, "little")


class _Server:
    """Answers one protocol's instruction packets on ``bus`` through :attr:`bus_table` and :attr:`servo_table`."""

    checksum_name = "checksum"
    checksum_error = P1_CHECKSUM_ERROR
    instruction_error = P1_INSTRUCTION_ERROR
    err_codes = P1_ERR
    skip_vanished_on_broadcast = False

    def __init__(self, bus: VirtualBus) -> None:
        self.bus = bus
        self.bus_table: dict[int, BusHandler] = {}
        self.servo_table: dict[int, ServoHandler] = {}

    def status(self, servo: SimServo, inst: int, code: int, params: bytes = b"") -> None:
        raise NotImplementedError

    def serve(self, pkt: framing.Packet) -> None:
        if not pkt.crc_ok:
            self.bus.stats["bad_checksum"] += 1
            self.bus._note(f"detected: bad {self.checksum_name} in instruction to id {pkt.servo_id}")
            servo = self.bus._present(pkt.servo_id)
            if servo is not None:
                self.status(servo, pkt.inst, self.checksum_error)
            return
        handler = self.bus_table.get(pkt.inst)
        if handler is None or not handler(pkt):
            self._each_servo(pkt)

    def _each_servo(self, pkt: framing.Packet) -> None:
        """A servo instruction on its target (every servo when broadcast; only unicast ones answer)."""
        sid, bus = pkt.servo_id, self.bus
        targets = bus.servos if sid == BROADCAST else [s for s in [bus._present(sid)] if s is not None]
        handler = self.servo_table.get(pkt.inst, self._unknown)
        for s in targets:
            if sid == BROADCAST and self.skip_vanished_on_broadcast and s.vanished:
                continue
            answer = handler(s, pkt.params)
            if answer is not None and sid != BROADCAST:
                self.status(s, pkt.inst, *answer)

    def _unknown(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return self.instruction_error, b""

    def write_checked(self, s: SimServo, addr: int, data: bytes) -> int:
        """``s.write``; a refused write is noted. Returns the servo's error code (0: written)."""
        code = s.write(addr, bytes(data))
        if code:
            what = {ERR_ACCESS: "access error", ERR_RANGE: "range error", ERR_LENGTH: "length error"}[code]
            self.bus._note(f"detected: id {s.id} refused write of {len(data)} bytes at address {addr} ({what})")
        return code

    def read(self, s: SimServo, addr: int, length: int) -> tuple[int, bytes]:
        """``s.read`` with the servo's error code translated to this protocol's."""
        code, data = s.read(addr, length)
        return self.err_codes.get(code, 0), data

    def read_each(self, ids: bytes, addr: int, length: int) -> None:
        """A sync read: each present servo of ``ids`` answers with its own READ status packet, in that order."""
        for i in ids:
            s = self.bus._present(i)
            if s is not None:
                self.status(s, READ, *self.read(s, addr, length))

    def reg_write(self, s: SimServo, addr: int, data: bytes) -> tuple[int, bytes]:
        """Hold a checked write until ACTION."""
        code = s.check_write(addr, data)
        if not code:
            s.registered = (addr, bytes(data))
        return self.err_codes.get(code, 0), b""


class Protocol2Server(_Server):
    """Dynamixel Protocol 2.0."""

    checksum_name = "CRC"
    checksum_error = P2_CRC_ERROR
    instruction_error = P2_INSTRUCTION_ERROR
    err_codes = P2_ERR
    skip_vanished_on_broadcast = True

    def __init__(self, bus: VirtualBus) -> None:
        super().__init__(bus)
        self.bus_table = {
            PING: self._ping, SYNC_WRITE: self._sync_write, SYNC_READ: self._sync_read,
            FAST_SYNC_READ: self._fast_sync_read, BULK_READ: self._bulk, BULK_WRITE: self._bulk,
        }  # fmt: skip
        self.servo_table = {
            READ: self._read, WRITE: self._write, REG_WRITE: self._reg_write, ACTION: self._action,
            REBOOT: self._reboot, FACTORY_RESET: self._factory_reset, CLEAR: lambda s, p: (0, b""),
        }  # fmt: skip

    def status(self, servo: SimServo, inst: int, code: int, params: bytes = b"") -> None:
        level = servo.get("status_level")
        if inst != PING and (level == 0 or (level == 1 and inst not in (READ, SYNC_READ, BULK_READ))):
            return
        err = code | (P2_ALERT if servo.hw_faults else 0)
        self.bus._emit(servo.id, framing.build2(servo.id, err, params), inst, servo.return_delay_s)

    # bus instructions
    def _ping(self, pkt: framing.Packet) -> bool:
        bus, sid = self.bus, pkt.servo_id
        targets = [s for s in bus.servos if bus._present(s.id)] if sid == BROADCAST else [bus._present(sid)]
        for s in sorted((t for t in targets if t is not None), key=lambda s: s.id):
            info = s.spec.model_number.to_bytes(2, "little") + bytes([s.get("Firmware_Version")])
            self.status(s, PING, 0, info)
        return True

    @staticmethod
    def _addr_length(p: bytes) -> tuple[int, int]:
        return int.from_bytes(p[0:2], "little"), int.from_bytes(p[2:4], "little")

    def _sync_write(self, pkt: framing.Packet) -> bool:
        p = pkt.params
        if len(p) >= 4:
            addr, length = self._addr_length(p)
            step = 1 + length
            for i in range(4, len(p) - step + 1, step):
                s = self.bus._present(p[i])
                if s is not None:
                    self.write_checked(s, addr, p[i + 1 : i + step])
        return True

    def _sync_read(self, pkt: framing.Packet) -> bool:
        p = pkt.params
        if len(p) >= 4:
            self.read_each(p[4:], *self._addr_length(p))
        return True

    def _fast_sync_read(self, pkt: framing.Packet) -> bool:
        """One status packet for all servos: per servo ``ERR ID DATA CRC``; the last CRC closes the packet."""
        p = pkt.params
        if len(p) < 4:
            return True
        addr, length = self._addr_length(p)
        servos = [self.bus._present(i) for i in p[4:]]
        present = [s for s in servos if s is not None]
        if len(present) < len(servos):
            self.bus._note("fast sync read: a servo is missing, packet not completed")
            return True
        out = bytearray([0xFF, 0xFF, 0xFD, 0x00, BROADCAST, 0, 0, 0x55])
        out[5:7] = (1 + (length + 4) * len(present)).to_bytes(2, "little")
        for k, s in enumerate(present):
            code, data = self.read(s, addr, length)
            out += bytes([code | (P2_ALERT if s.hw_faults else 0), s.id]) + data
            if k < len(present) - 1:
                out += crc16_bytes(out)
        out += crc16_bytes(out)
        self.bus._emit(BROADCAST, bytes(out), FAST_SYNC_READ, present[0].return_delay_s if present else 0.0)
        return True

    def _bulk(self, pkt: framing.Packet) -> bool:
        """BULK_READ / BULK_WRITE: per servo ``ID ADDR(2) LEN(2)`` (and the data, for a write)."""
        p, i = pkt.params, 0
        while i + 5 <= len(p):
            s = self.bus._present(p[i])
            addr, length = self._addr_length(p[i + 1 : i + 5])
            if pkt.inst == BULK_READ:
                if s is not None:
                    self.status(s, READ, *self.read(s, addr, length))
                i += 5
            else:
                if s is not None:
                    self.write_checked(s, addr, p[i + 5 : i + 5 + length])
                i += 5 + length
        return True

    # servo instructions
    def _read(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return self.read(s, *self._addr_length(p)) if len(p) == 4 else self._unknown(s, p)

    def _write(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        if len(p) < 3:
            return self._unknown(s, p)
        return self.err_codes.get(self.write_checked(s, int.from_bytes(p[0:2], "little"), p[2:]), 0), b""

    def _reg_write(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return self.reg_write(s, int.from_bytes(p[0:2], "little"), p[2:]) if len(p) >= 3 else self._unknown(s, p)

    def _action(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        if s.registered is None:
            return P2_INSTRUCTION_ERROR, b""
        s.write(*s.registered)
        s.registered = None
        return 0, b""

    def _reboot(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        s.reboot()
        return 0, b""

    def _factory_reset(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return (P2_INSTRUCTION_ERROR if s.torque_on else 0), b""


class Protocol1Server(_Server):
    """Dynamixel Protocol 1.0 and Feetech (SCS/STS): one-byte addresses, a checksum instead of a CRC."""

    def __init__(self, bus: VirtualBus) -> None:
        super().__init__(bus)
        self.bus_table = {SYNC_WRITE: self._sync_write, SYNC_READ: self._sync_read, BULK_READ: self._bulk_read,
                          PING: self._broadcast_ping}  # fmt: skip
        self.servo_table = {
            PING: lambda s, p: (0, b""), READ: self._read, WRITE: self._write, REG_WRITE: self._reg_write,
            ACTION: self._action, FACTORY_RESET: lambda s, p: (0, b""),
        }  # fmt: skip

    def status(self, servo: SimServo, inst: int, code: int, params: bytes = b"") -> None:
        level = servo.get("status_level")
        if self.bus.family == "feetech":
            if inst not in (PING, READ) and level == 0:
                return
        elif inst != PING and (level == 0 or (level == 1 and inst != READ)):
            return
        pkt = framing.build1(servo.id, code | servo.hw_error_bits_p1(), params)
        self.bus._emit(servo.id, pkt, inst, servo.return_delay_s)

    # bus instructions
    def _sync_write(self, pkt: framing.Packet) -> bool:
        p = pkt.params
        if len(p) < 2:
            return False
        addr, length = p[0], p[1]
        for i in range(2, len(p) - length, 1 + length):
            s = self.bus._present(p[i])
            if s is not None:
                self.write_checked(s, addr, p[i + 1 : i + 1 + length])
        return True

    def _sync_read(self, pkt: framing.Packet) -> bool:
        """Feetech only (Protocol 1.0 Dynamixels have no sync read)."""
        p = pkt.params
        if self.bus.family != "feetech" or len(p) < 2:
            return False
        self.read_each(p[2:], p[0], p[1])
        return True

    def _bulk_read(self, pkt: framing.Packet) -> bool:
        """Dynamixel only: 0x00, then ``(length, id, address)`` per servo."""
        p = pkt.params
        if self.bus.family != "dynamixel" or len(p) < 1:
            return False
        for i in range(1, len(p) - 2, 3):
            s = self.bus._present(p[i + 1])
            if s is not None:
                self.status(s, READ, *self.read(s, p[i + 2], p[i]))
        return True

    def _broadcast_ping(self, pkt: framing.Packet) -> bool:
        if pkt.servo_id != BROADCAST:
            return False  # a unicast ping is a servo instruction
        for s in self.bus.servos:
            if self.bus._present(s.id):
                self.status(s, PING, 0)
        return True

    # servo instructions
    def _read(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return self.read(s, p[0], p[1]) if len(p) == 2 else self._unknown(s, p)

    def _write(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return (self.err_codes.get(self.write_checked(s, p[0], p[1:]), 0), b"") if len(p) >= 2 else self._unknown(s, p)

    def _reg_write(self, s: SimServo, p: bytes) -> tuple[int, bytes]:
        return self.reg_write(s, p[0], p[1:]) if len(p) >= 2 else self._unknown(s, p)

    def _action(self, s: SimServo, p: bytes) -> None:
        """Runs the registered write; ACTION never answers."""
        if s.registered is not None:
            s.write(*s.registered)
            s.registered = None
