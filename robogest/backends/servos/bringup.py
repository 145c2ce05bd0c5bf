"""Bring-up of a real servo bus: find the servos (scan) and check what commonly breaks a bus (doctor).

Both work below the robot abstraction on a :class:`~.transport.Transport` (one port, one protocol, one baud rate,
exclusively opened), because the point is to find out what the bus really holds before a robot YAML can
be trusted. Ticks and raw register values appear here; joint radians only where a robot is given.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from enum import Enum
from pathlib import Path
from typing import Any

from robogest.backends.servos.protocol import PROTOCOL_NAMES, ServoProtocol
from robogest.backends.servos.transport import Transport
from robogest.errors import BackendError, ConfigError, InputError
from robogest.robot.config import BusConfig, RobotConfig

#: ``progress(done, total, what)``: called before each try of a scan.
Progress = Callable[[int, int, str], None]

DXL2, DXL1, STS, SCS = ServoProtocol.DXL2, ServoProtocol.DXL1, ServoProtocol.STS, ServoProtocol.SCS
#: Protocols in the order they are tried: the most common first, Protocol 1.0 (no usable broadcast ping) last.
PROTOCOLS = tuple(ServoProtocol.named(n) for n in PROTOCOL_NAMES)
#: Baud rates per protocol, the factory defaults and the most common settings first.
COMMON_BAUDS = {
    DXL2: (57_600, 1_000_000, 115_200, 2_000_000, 3_000_000, 4_000_000, 9_600),
    STS: (1_000_000, 500_000, 115_200, 57_600, 250_000, 128_000, 38_400, 19_200),
    SCS: (1_000_000, 500_000, 115_200, 57_600, 250_000, 128_000, 38_400, 19_200),
    DXL1: (1_000_000, 57_600, 115_200, 9_600, 2_000_000),
}
#: Protocols with one packet format (Dynamixel Protocol 1.0's, which Feetech took over; only the byte order of
#: values differs): a servo answers a ping in each of them.
SAME_PACKETS = (STS, SCS, DXL1)


def write_eeprom(link: Transport, sid: int, reg: Enum, value: int) -> None:
    """An EEPROM write that sticks: torque off first; on Feetech, Lock opened for it and restored after."""
    link.write(sid, link.wire.reg("TORQUE_ENABLE"), 0)
    lock = link.wire.reg("LOCK") if "LOCK" in link.wire.registers.__members__ else None
    was = link.read(sid, lock) if lock is not None else None
    if lock is not None and was:
        link.write(sid, lock, 0)
    try:
        err = link.write(sid, reg, value)
    finally:
        if lock is not None and was:
            link.write(sid, lock, was)
    if err:
        raise BackendError(f"servo id {sid}: {reg.name} refused value {value} (error byte 0x{err:02X})")


def broadcast_ping(link: Transport, max_id: int = 252) -> list[int]:
    """Ids that answer one broadcast PING, in one round trip (each servo answers in its own time slot).

    Waits for ids up to ``max_id``: 3 ms per id on Dynamixel 2.0 (as the SDK allows), 1 ms elsewhere, + 50 ms.
    """
    _fresh(link)
    if link.protocol is DXL2:
        pkt = [0] * 10
        pkt[4], pkt[5], pkt[6], pkt[7] = 0xFE, 3, 0, 1  # id, length, instruction PING
        wait_ms = 3.0 * max_id + 50.0
    else:
        pkt = [0] * 6
        pkt[2], pkt[3], pkt[4] = 0xFE, 2, 1
        wait_ms = 1.0 * max_id + 50.0
    if not link.ok(link.ph.txPacket(link.port, pkt)):
        raise BackendError(f"cannot write to {link.port_name}")
    id_at = link.wire.status_layout[0]
    found: set[int] = set()
    t_end = time.monotonic() + wait_ms / 1000.0
    while time.monotonic() < t_end:
        link.port.setPacketTimeoutMillis(max(1.0, (t_end - time.monotonic()) * 1000.0))
        pkt_in, ok = link.rx_packet()
        link.port.is_using = False
        if ok and len(pkt_in) > id_at:
            found.add(int(pkt_in[id_at]))
        elif not pkt_in:
            break  # nothing more within the wait
    return sorted(found)


def ping_each(link: Transport, ids: range, timeout_ms: float) -> list[int]:
    """Ids that answer a read of their Model Number, asked one by one with a short timeout."""
    model = link.wire.reg("MODEL_NUMBER")
    found = []
    for sid in ids:
        _fresh(link)
        if not link.ok(link.ph.readTx(link.port, sid, *model.value)):
            continue
        link.port.setPacketTimeoutMillis(timeout_ms)
        _, ok = link.rx_packet()
        link.port.is_using = False
        if ok:
            found.append(sid)
    return found


def _fresh(link: Transport) -> None:
    """Before a request whose answers are not matched one to one (pings): the input emptied."""
    link.prep()
    link.port.ser.reset_input_buffer()


def baud_register_value(protocol: ServoProtocol, baud: int) -> int:
    """The Baud Rate register value that selects ``baud``."""
    from robogest.backends.servos.dynamixel.tables import X_BAUDRATES
    from robogest.backends.servos.feetech.tables import FT_BAUDRATES

    if protocol is DXL1:
        return round(2_000_000 / baud - 1)  # AX/MX: baud = 2 Mbps / (value + 1)
    table = X_BAUDRATES if protocol is DXL2 else FT_BAUDRATES
    value = next((v for v, b in table.items() if b == baud), None)
    if value is None:
        rates = ", ".join(map(str, table.values()))
        raise InputError(f"{protocol.cli_name} servos cannot be set to {baud} baud; one of {rates}")
    return value


def set_baud(port: str, protocol: ServoProtocol, sid: int, old_baud: int, new_baud: int) -> None:
    """Move one servo from ``old_baud`` to ``new_baud`` (torque off; a Feetech Lock is restored at the new rate)."""
    value = baud_register_value(protocol, new_baud)
    with Transport(port, protocol, old_baud) as link:
        link.write(sid, link.wire.reg("TORQUE_ENABLE"), 0)
        lock = link.wire.reg("LOCK") if protocol.family == "feetech" else None
        was = link.read(sid, lock) if lock is not None else 0
        if was and lock is not None:
            link.write(sid, lock, 0)
        try:
            err = link.write(sid, link.wire.reg("BAUD_RATE"), value, attempts=1)
        except BackendError:  # no reply at the old rate: it may already come at the new one (checked below)
            err = 0
        if err:
            raise BackendError(
                f"servo id {sid}: refused the Baud Rate write (status error 0x{err:02X}); a servo whose EEPROM is "
                "locked (Dynamixel AX/MX Lock = 1) keeps its settings until it is powered off and on again"
            )
    time.sleep(0.05)
    with Transport(port, protocol, new_baud) as link:
        link.read(sid, link.wire.reg("MODEL_NUMBER"))  # answers at the new rate, or raises naming the servo
        if was and lock is not None:
            link.write(sid, lock, was)


@dataclass
class FoundServo:
    """One servo that answered a scan. Limits in ticks, as stored in the servo."""

    protocol: ServoProtocol
    baud: int
    id: int
    model_number: int
    model: str
    firmware: int
    return_delay_us: float
    min_position_tick: int
    max_position_tick: int

    def line(self) -> str:
        return (
            f"{self.protocol.cli_name:4s} {self.baud:8d} baud  id {self.id:3d}  {self.model} ({self.model_number})  "
            f"firmware {self.firmware}  return delay {self.return_delay_us:.0f} us  "
            f"limits [{self.min_position_tick}, {self.max_position_tick}] ticks"
        )

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "protocol": self.protocol.cli_name}


def describe(link: Transport, sid: int) -> FoundServo:
    """Read what a scan reports about one servo."""
    number = link.read(sid, link.wire.reg("MODEL_NUMBER"))
    fw = link.read(sid, link.wire.reg("FIRMWARE_VERSION", "FIRMWARE_MAJOR_VERSION"))
    rdt = link.read(sid, link.wire.reg("RETURN_DELAY_TIME"))
    lo = link.read(sid, link.wire.reg("MIN_POSITION_LIMIT", "CW_ANGLE_LIMIT"))
    hi = link.read(sid, link.wire.reg("MAX_POSITION_LIMIT", "CCW_ANGLE_LIMIT"))
    model = link.wire.model_named(number)
    return FoundServo(link.protocol, link.baudrate, sid, number, model, fw, 2.0 * rdt, lo, hi)


def scan(
    port: str,
    protocols: list[ServoProtocol] | None = None,
    bauds: list[int] | None = None,
    *,
    max_id: int = 252,
    per_id: bool = False,
    timeout_ms: float = 10.0,
    progress: Progress | None = None,
    all_protocols: bool = False,
) -> list[FoundServo]:
    """Every servo that answers on ``port``, trying each protocol at each baud rate (common ones first).

    One broadcast ping per protocol and baud (Protocol 1.0, whose servos do not answer broadcasts, and
    ``per_id`` ask ids ``0..max_id`` one by one with ``timeout_ms``, raised above the USB adapter's latency
    timer). Protocols after the first one that answered are skipped unless ``all_protocols``.
    ``progress(done, total, what)`` is called before each try.
    """
    protocols = protocols or list(PROTOCOLS)
    tries = [(p, b) for p in protocols for b in (bauds or COMMON_BAUDS[p])]
    found: list[FoundServo] = []
    timer = latency_timer_path(port)  # a USB adapter holds a short reply back this long
    latency_ms = float(timer.read_text().strip() or 0) if timer is not None else 0.0
    for k, (proto, baud) in enumerate(tries):
        if found and not all_protocols and proto != found[-1].protocol:
            break  # every baud of the protocol that answered is done; one bus rarely mixes protocols
        if progress:
            progress(k, len(tries), f"{proto.cli_name} at {baud} baud")
        try:
            link = Transport(port, proto, baud)
        except InputError:
            continue  # a rate this SDK cannot set
        with link:
            if per_id or proto is DXL1:
                ids = ping_each(link, range(0, max_id + 1), max(timeout_ms, latency_ms + 4.0))
            else:
                ids = broadcast_ping(link, max_id)
            for sid in ids:
                with contextlib.suppress(BackendError):
                    found.append(describe(link, sid))
    if progress:
        progress(len(tries), len(tries), "done")
    return one_per_servo(found)


def one_per_servo(found: list[FoundServo]) -> list[FoundServo]:
    """Each servo once: one that answered several protocols of :data:`SAME_PACKETS` at one baud rate and id (a
    Feetech STS servo answers STS, SCS and Dynamixel 1.0 pings: ``scan --all`` listed it three times) is kept under
    the protocol whose table knows its model number (the first that does, or the first that answered)."""
    out: list[FoundServo] = []
    slot: dict[tuple[int, int], int] = {}  # (baud, id) -> index in out
    for f in found:
        if f.protocol not in SAME_PACKETS:
            out.append(f)
            continue
        k = slot.get((f.baud, f.id))
        if k is None:
            slot[(f.baud, f.id)] = len(out)
            out.append(f)
        elif out[k].model == "?" and f.model != "?":
            out[k] = f
    return out


@dataclass
class JointServo:
    """One row of ``servo scan --robot``: the servo a joint's YAML entry expects against what answered at its id.

    ``joint`` is None for an id that answered but no joint has; ``found_model`` is None when nothing answered."""

    joint: str | None
    id: int
    expected_model: str | None
    found_model: str | None
    ok: bool

    @property
    def status(self) -> str:
        if self.joint is None:
            return "UNEXPECTED (no joint has this id)"
        if self.found_model is None:
            return "MISSING (nothing answers at this id)"
        return "ok" if self.ok else f"WRONG MODEL (expected {self.expected_model})"

    def line(self) -> str:
        return (
            f"{self.joint or '-':20s} id {self.id:3d}  expected {self.expected_model or '-':12s} "
            f"found {self.found_model or '-':12s} {self.status}"
        )

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "status": self.status.split(" ")[0].lower()}


def scan_robot(
    port: str,
    robot: RobotConfig,
    bauds: list[int],
    *,
    max_id: int = 252,
    per_id: bool = False,
    progress: Progress | None = None,
) -> list[FoundServo]:
    """What answers on ``port`` at ``robot``'s bus protocol and each of ``bauds``: a :func:`scan`, then each id a
    joint expects that the scan did not hear is asked once more on its own (a broadcast reply lost on a busy bus
    would otherwise read as a missing servo)."""
    bus = _bus_of(robot)
    proto = ServoProtocol.of_bus(bus.family, bus.protocol)
    found = scan(port, [proto], bauds, max_id=max_id, per_id=per_id, progress=progress)
    heard = {f.id for f in found}
    for baud in bauds:
        missing = sorted({s.id for s in bus.servos.values()} - heard)
        if not missing:
            break
        with Transport(port, proto, baud) as link:
            for sid in missing:
                with contextlib.suppress(BackendError):
                    found.append(describe(link, sid))
                    heard.add(sid)
    return found


def _bus_of(robot: RobotConfig) -> BusConfig:
    if robot.bus is None:
        raise ConfigError(f"{robot.path or robot.name}: no bus section, so no servos to look for; add one")
    return robot.bus


def model_numbers(bus: BusConfig) -> dict[str, int | None]:
    """Per joint of ``bus.servos``, the Model Number its YAML model has; None for a model the family's backend does not
    know (`robots validate` reports it; callers compare by name instead) or a backend without a model table."""
    from robogest.backends.base import get_backend_factory

    lookup = getattr(get_backend_factory(bus.family), "lookup_model", None)
    out: dict[str, int | None] = {}
    for joint, s in bus.servos.items():
        try:
            out[joint] = int(lookup(s.model, bus.protocol).number) if lookup is not None else None
        except ConfigError:
            out[joint] = None
    return out


def match_robot(robot: RobotConfig, found: list[FoundServo]) -> list[JointServo]:
    """Per joint of ``robot`` (its ``bus.servos``, YAML order), the expected id and model against ``found``; then
    every id that answered but no joint has. A model matches by its model number (names differ in spelling)."""
    bus = _bus_of(robot)
    numbers = model_numbers(bus)
    by_id = {f.id: f for f in found}
    rows = []
    for joint in robot.joint_names:
        s = bus.servos[joint]
        number = numbers[joint]
        f = by_id.get(s.id)
        ok = f is not None and (f.model_number == number if number is not None else f.model == s.model)
        rows.append(JointServo(joint, s.id, s.model, None if f is None else f.model, ok))
    ids = {s.id for s in bus.servos.values()}
    rows += [JointServo(None, f.id, None, f.model, False) for f in found if f.id not in ids]
    return rows


# --- doctor ------------------------------------------------------------------------------------------
@dataclass
class Finding:
    """One line of ``servo doctor``: ``ok`` / ``warn`` / ``fixed`` / ``error``, what, and how to fix it."""

    level: str
    what: str

    def line(self) -> str:
        return f"{self.level:5s} {self.what}"


def latency_timer_path(port: str) -> Path | None:
    """The sysfs latency-timer file of a USB-serial adapter (FTDI and friends), or None for other ports."""
    name = Path(os.path.realpath(port)).name
    path = Path("/sys/bus/usb-serial/devices") / name / "latency_timer"
    return path if path.exists() else None


def check_latency_timer(port: str, fix: bool) -> Finding:
    path = latency_timer_path(port)
    if path is None:
        return Finding("ok", f"latency timer: {port} is not a USB-serial adapter with one (nothing to check)")
    ms = int(path.read_text().strip() or 0)
    if ms <= 1:
        return Finding("ok", f"latency timer: {ms} ms")
    cmd = f"echo 1 | sudo tee {path}"
    if fix:
        try:
            path.write_text("1\n")
            return Finding("fixed", f"latency timer: {ms} ms -> 1 ms (lasts until the adapter is replugged)")
        except OSError:
            return Finding("error", f"latency timer: {ms} ms and no permission to change it; run: {cmd}")
    return Finding(
        "warn",
        f"latency timer: {ms} ms (each reply waits up to {ms} ms: a read-write loop caps near "
        f"{1000 // (2 * ms + 2)} Hz); fix: --fix, or run: {cmd}",
    )
