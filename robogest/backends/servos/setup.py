"""Bring-up before a robot YAML can be trusted: which serial port is the robot's (``servo find-port``), and each
servo's id and baud rate from the YAML, written one servo at a time (``servo setup``), as LeRobot users know them
from ``lerobot-find-port`` and ``lerobot-setup-motors``.

New servos all leave the factory with the same id (1 on Feetech and Dynamixel X), so they can only be told apart
one at a time: the user connects one servo, it is found at whatever id and baud rate it has, and its id and baud
rate are written, then checked. Torque is switched off and never on. Writing one servo is one step that a Ctrl-C
does not cut in half: the interrupt waits until the servo has its new settings and is checked, then says so.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from robogest.backends.servos.bringup import (
    COMMON_BAUDS,
    FoundServo,
    Progress,
    baud_register_value,
    model_numbers,
    scan,
)
from robogest.backends.servos.protocol import ServoProtocol
from robogest.backends.servos.transport import Transport
from robogest.errors import BackendError, ConfigError, InputError
from robogest.robot.config import RobotConfig

Ask = Callable[[str], object]
Say = Callable[[str], None]


# --- serial ports ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SerialPort:
    """One serial port as the OS lists it; ``usb``: a USB adapter (the servo buses robogest drives)."""

    device: str
    description: str
    usb: bool

    def line(self) -> str:
        return f"{self.device}  {self.description or '-'}" + ("" if self.usb else "  (not USB)")


def list_ports() -> list[SerialPort]:
    """Serial ports from pyserial's ``serial.tools.list_ports``, by device name."""
    from serial.tools import list_ports as lp

    ports = [SerialPort(p.device, p.description or "", p.vid is not None) for p in lp.comports()]
    return sorted(ports, key=lambda p: p.device)


def the_one_port(lister: Callable[[], list[SerialPort]] = list_ports, what: str = "servo scan") -> str:
    """The one USB serial port there is; otherwise InputError listing the ports and asking for ``--port``."""
    ports = lister()
    usb = [p for p in ports if p.usb]
    if len(usb) == 1:
        return usb[0].device
    listed = "; ".join(p.line() for p in ports) or "none"
    why = "no USB serial port is plugged in" if not usb else f"{len(usb)} USB serial ports are plugged in"
    raise InputError(
        f"{what} needs --port PATH: {why} (serial ports: {listed}); `robogest servo find-port` tells which is the "
        "robot's"
    )


def find_port(ask: Ask, say: Say, lister: Callable[[], list[SerialPort]] = list_ports, settle_s: float = 0.5) -> str:
    """The port that vanishes while the user unplugs the robot's USB adapter (lists, asks, lists again)."""
    before = lister()
    say("serial ports now:" if before else "no serial port now")
    for p in before:
        say(f"  {p.line()}")
    if not before:
        raise BackendError("no serial port found; plug in the servo adapter's USB cable, then run find-port again")
    ask("Unplug the USB cable of the robot's servo adapter (the servos' power can stay on), then press Enter: ")
    time.sleep(settle_s)  # the OS takes a moment to remove the device
    after = {p.device for p in lister()}
    gone = [p for p in before if p.device not in after]
    if len(gone) == 1:
        say(f"the robot's port is {gone[0].device}; plug the cable back in")
        say(f"next: robogest servo scan --port {gone[0].device}  (or set bus.port: {gone[0].device} in the robot YAML)")
        return gone[0].device
    if not gone:
        raise BackendError(
            "no port vanished: was the adapter's USB cable unplugged (not the servos' power)? Run find-port again"
        )
    raise BackendError(
        f"{len(gone)} ports vanished ({', '.join(p.device for p in gone)}): unplug only the robot's adapter, then run "
        "find-port again"
    )


# --- setup: one servo at a time ------------------------------------------------------------------------
@dataclass(frozen=True)
class Target:
    """What the robot YAML wants of one joint's servo."""

    joint: str
    id: int
    model: str
    model_number: int | None
    baud: int


def targets(robot: RobotConfig, joints: list[str] | None = None) -> list[Target]:
    """The servos to set up, in the YAML's joint order (``joints``: only these); InputError for a joint the robot
    lacks or a baud rate its servos cannot be set to."""
    bus = robot.bus
    if bus is None:
        raise ConfigError(f"{robot.path or robot.name}: no bus section, so no servos to set up; add one")
    proto = ServoProtocol.of_bus(bus.family, bus.protocol)
    baud_register_value(proto, bus.baudrate)  # raises before anything is written
    unknown = [j for j in joints or [] if j not in robot.joint_names]
    if unknown:
        raise InputError(f"robot {robot.name} has no joints {unknown}; its joints: {', '.join(robot.joint_names)}")
    numbers = model_numbers(bus)  # None: compared by name; `robots validate` reports the unknown model
    out = []
    for joint in robot.joint_names:
        if joints and joint not in joints:
            continue
        s = bus.servos[joint]
        out.append(Target(joint, s.id, s.model, numbers[joint], bus.baudrate))
    return out


@contextlib.contextmanager
def signals_wait() -> Iterator[list[int]]:
    """Within the block, SIGINT and SIGTERM are noted (in the yielded list) instead of raising: a servo write is
    never cut in half. The caller says what state the servo is in, then raises."""
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    caught: list[int] = []
    old = {s: signal.signal(s, lambda signum, _: caught.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield caught
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def interrupted(message: str, signum: int = signal.SIGINT) -> KeyboardInterrupt:
    """A KeyboardInterrupt the CLI prints as ``robogest: MESSAGE``, exit 128 + signum (130 for Ctrl-C)."""
    e = KeyboardInterrupt(message)
    e.exit_code = 128 + signum  # type: ignore[attr-defined]
    return e


def lone_servo(
    port: str, proto: ServoProtocol, target: Target, max_id: int, progress: Progress | None = None
) -> FoundServo | str:
    """The one servo on the bus at any id and baud rate, or why not (a line for the user): none answers, more than
    one does, or it is another model than the YAML's."""
    found = scan(port, [proto], list(dict.fromkeys([target.baud, *COMMON_BAUDS[proto]])), max_id=max_id,
                 progress=progress)  # fmt: skip
    if not found:
        return f"no servo answers on {port} ({proto}, any baud rate, ids 0..{max_id}); check its cable and power"
    if len(found) > 1:
        which = ", ".join(f"id {f.id} at {f.baud} baud" for f in found)
        return f"{len(found)} servos answer ({which}); connect only joint {target.joint}'s servo"
    f = found[0]
    same = f.model_number == target.model_number if target.model_number is not None else f.model == target.model
    if not same:
        return (
            f"the servo connected is a {f.model} ({f.model_number}) where joint {target.joint}'s YAML entry says "
            f"{target.model}; connect joint {target.joint}'s servo, or fix the YAML; nothing written"
        )
    return f


def assign(port: str, proto: ServoProtocol, f: FoundServo, target: Target) -> None:
    """Write ``target``'s id and baud rate into the servo ``f`` (torque off; Feetech: EEPROM unlocked for it and
    locked again as it was), then check it answers at both. BackendError naming where it answers when not."""
    with Transport(port, proto, f.baud) as link:
        link.write(f.id, link.wire.reg("TORQUE_ENABLE"), 0)
        lock = link.wire.reg("LOCK") if proto.family == "feetech" else None  # Feetech: Lock 0 = EEPROM writes are kept
        was = link.read(f.id, lock) if lock is not None else 0
        if was and lock is not None:
            link.write(f.id, lock, 0)
        sid = f.id
        for reg, value, new_sid in (
            ("ID", target.id, target.id),
            ("BAUD_RATE", baud_register_value(proto, target.baud), target.id),
        ):
            if (reg == "ID" and f.id == target.id) or (reg == "BAUD_RATE" and f.baud == target.baud):
                continue
            try:  # the reply may come from the new id, or at the new baud rate: checked below instead
                err = link.write(sid, link.wire.reg(reg), value, attempts=1)
            except BackendError:
                err = 0
            if err:
                raise BackendError(
                    f"servo id {sid}: refused the {reg} write (status error 0x{err:02X}); a Dynamixel AX/MX with "
                    "Lock = 1 keeps its settings until it is powered off and on again"
                )
            sid = new_sid
            if reg == "ID":
                link.read(sid, link.wire.reg("MODEL_NUMBER"))  # answers at its new id, or raises
    time.sleep(0.05)  # the servo switches its baud rate after the reply
    with Transport(port, proto, target.baud) as link:
        if link.read(target.id, link.wire.reg("ID")) != target.id:
            raise BackendError(f"servo id {target.id}: its ID register does not read {target.id}")
        if was and lock is not None:
            link.write(target.id, lock, was)


def where_now(port: str, proto: ServoProtocol, f: FoundServo, target: Target) -> str:
    """Which settings the servo answers with now: its old ones, the new ones, or the new id at the old baud rate."""
    for sid, baud, what in (
        (target.id, target.baud, "its new settings"),
        (f.id, f.baud, "its old settings"),
        (target.id, f.baud, "the new id but its old baud rate"),
    ):
        with contextlib.suppress(BackendError, InputError), Transport(port, proto, baud) as link:
            link.read(sid, link.wire.reg("MODEL_NUMBER"), attempts=2)
            return f"{what} (id {sid} at {baud} baud)"
    return "no answer at its old or new settings"


def setup_servos(
    port: str,
    robot: RobotConfig,
    ask: Ask,
    say: Say,
    *,
    joints: list[str] | None = None,
    max_id: int = 252,
    progress: Progress | None = None,
) -> list[str]:
    """Guide the user through connecting each joint's servo alone and write its id and baud rate (module docstring).
    Returns the joints set up. A Ctrl-C leaves the servo being written old or new, never half, and says which."""
    todo = targets(robot, joints)  # raises for a robot without a bus section
    assert robot.bus is not None
    proto = ServoProtocol.of_bus(robot.bus.family, robot.bus.protocol)
    done: list[str] = []
    for t in todo:
        rest = ", ".join(x.joint for x in todo[len(done) :])
        try:
            prompt = f"Connect ONLY the servo of joint {t.joint} ({t.model}, to become id {t.id}) and unplug every "
            ask(prompt + "other servo from the bus, then press Enter: ")
            found = lone_servo(port, proto, t, max_id, progress)
            while isinstance(found, str):
                say(found)
                ask("Press Enter to look again (Ctrl-C stops; the servos done so far keep their settings): ")
                found = lone_servo(port, proto, t, max_id, progress)
        except KeyboardInterrupt as e:
            raise interrupted(
                f"stopped before writing joint {t.joint}'s servo: it is unchanged; not set up: {rest}",
                getattr(e, "exit_code", 130) - 128,
            ) from None
        if found.id == t.id and found.baud == t.baud:
            say(f"{t.joint}: already id {t.id} at {t.baud} baud; nothing written")
            done.append(t.joint)
            continue
        with signals_wait() as caught:
            try:
                assign(port, proto, found, t)
            except BackendError as e:
                now = where_now(port, proto, found, t)
                so_far = ", ".join(done) or "none"
                raise BackendError(f"joint {t.joint}'s servo: {e}; it answers with {now}; set up: {so_far}") from None
        done.append(t.joint)
        say(f"{t.joint}: id {found.id} -> {t.id}, {found.baud} -> {t.baud} baud; checked, torque off")
        if caught:
            left = ", ".join(x.joint for x in todo[len(done) :]) or "none"
            raise interrupted(
                f"stopped after joint {t.joint}'s servo got its new settings (id {t.id} at {t.baud} baud, checked); "
                f"not set up: {left}",
                caught[0],
            )
    return done
