"""``robogest servo ping|read|write``: one servo, one register, raw, over the servo backends' transport (the same
byte order, late-reply matching and retries as the backends and bring-up); with ``--robot``, writes are checked
against the joint's limits."""

from __future__ import annotations

import argparse
import math
from enum import Enum
from typing import TYPE_CHECKING, Any

from robogest.cli import checks
from robogest.errors import BackendError, ConfigError, InputError, SafetyError

if TYPE_CHECKING:
    from robogest.backends.servos.bus import ServoBackend
    from robogest.backends.servos.protocol import ServoProtocol
    from robogest.backends.servos.transport import Transport
    from robogest.backends.servos.wire import Wire
    from robogest.robot.config import RobotConfig

#: ``--protocol`` choices: ``ServoProtocol`` names (robogest.backends.servos.protocol.PROTOCOL_NAMES, spelled out
#: here so that building the parser imports no backend).
PROTOCOL_CHOICES = ("dxl2", "sts", "scs", "dxl1")


def add_raw_parsers(ss: Any) -> None:
    """``servo ping``, ``servo read`` and ``servo write``: one servo, one register."""
    for name in ("ping", "read", "write"):
        p = ss.add_parser(
            name,
            help=f"{name} one servo",
            epilog="With --robot, a goal outside that joint's limits, torque on with the goal away from the servo, "
            "and any register other than GOAL_POSITION, TORQUE_ENABLE and LED are refused (exit 4) and nothing is "
            "written. Values are range-checked and written in the register's encoding; an ID already taken on the "
            "bus is refused."
            if name == "write"
            else None,
        )
        p.add_argument("--port", required=True)
        p.add_argument("--id", type=checks.number(0, 253, integer=True), required=True, help="servo id, 0..253")
        robot_s = "the --robot's, else " if name == "write" else ""
        p.add_argument("--protocol", choices=PROTOCOL_CHOICES, default=None, help=f"default: {robot_s}dxl2")
        p.add_argument("--baud", type=checks.baud, default=None, help=f"default: {robot_s}1000000")
        if name == "write":
            p.add_argument("--robot", help="robot name or YAML path: a goal is checked against its joint limits and "
                           "sent with the joint's speed and acceleration caps, torque goes on only with the goal near "
                           "the servo; only GOAL_POSITION, TORQUE_ENABLE and LED are taken (without it: raw "
                           "registers)")  # fmt: skip
        if name != "ping":
            g = p.add_mutually_exclusive_group(required=True)
            g.add_argument("--register", help="register name, e.g. PRESENT_POSITION")
            g.add_argument("--addr", type=checks.number(0, 65535, integer=True), help="raw address (needs --size)")
            p.add_argument("--size", type=int, choices=(1, 2, 4), default=None, help="bytes at --addr: 1, 2 or 4")
        if name == "write":
            p.add_argument("--value", type=checks.number(-(2**31), 2**32 - 1, integer=True), required=True)
        p.set_defaults(func=one)


def _link(port: str, protocol: ServoProtocol, baud: int) -> Transport:
    from robogest.backends.servos.transport import Transport

    return Transport(port, protocol, baud)


def _answers(link: Transport, sid: int) -> bool:
    """Whether a servo answers at id ``sid`` (its Model Number is read)."""
    try:
        link.read(sid, link.wire.reg("MODEL_NUMBER"), attempts=2)
    except BackendError:
        return False
    return True


def _resolve(link: Transport, args: argparse.Namespace) -> tuple[str, int, int]:
    """``(name, address, size)`` of ``--register`` or ``--addr``/``--size``."""
    if args.register:
        regs = link.wire.registers
        key = args.register.upper()
        if key not in regs.__members__:
            raise InputError(
                f"unknown register {args.register!r} for {link.protocol.cli_name}; one of {', '.join(regs.__members__)}"
            )
        addr, size = regs[key].value
        return key, addr, size
    if args.size is None:  # a 1-byte default read the low byte of a 4-byte register, and wrote it alone
        raise InputError(f"--addr {args.addr} needs --size 1, 2 or 4 (the register's width in bytes), or --register")
    return f"address {args.addr}", args.addr, args.size


def _robot_protocol(robot: RobotConfig) -> ServoProtocol:
    """The protocol of a robot's bus."""
    from robogest.backends.servos.protocol import ServoProtocol

    assert robot.bus is not None
    return ServoProtocol.of_bus(robot.bus.family, robot.bus.protocol)


def _joint_of_servo(robot: RobotConfig, args: argparse.Namespace) -> tuple[ServoBackend, int]:
    """``(backend, k)``: the robot's backend (its rad/tick mapping only; opens nothing) and the index of the joint
    that servo ``args.id`` moves."""
    from robogest.backends.servos.bus import servo_backend

    backend = servo_backend(robot, port=args.port)
    assert robot.bus is not None  # servo_backend checked it
    joints = {s.id: j for j, s in robot.bus.servos.items()}
    if args.id not in joints:
        raise InputError(f"servo id {args.id} is not in robot {robot.name} (ids {sorted(joints)}); check --id")
    return backend, robot.joint_names.index(joints[args.id])


def _check_goal_write(
    robot: RobotConfig, args: argparse.Namespace, name: str, addr: int, size: int, wire: Wire
) -> None:
    """Refuse (nothing written) a goal-position write outside the joint limits of the servo's joint in ``robot``."""
    g_addr, g_size = wire.reg("GOAL_POSITION").value
    if not (addr < g_addr + g_size and g_addr < addr + size):
        return  # does not touch the goal position
    if (addr, size) != (g_addr, g_size):
        raise SafetyError(
            f"servo id {args.id}: writing {name} overlaps GOAL_POSITION; write it as --register GOAL_POSITION so it "
            f"can be checked against robot {robot.name}'s joint limits"
        )
    import numpy as np

    backend, k = _joint_of_servo(robot, args)
    ends = backend.rad_to_ticks(robot.q_min_rad)[k], backend.rad_to_ticks(robot.q_max_rad)[k]
    lo, hi = int(min(ends)), int(max(ends))
    if not lo <= args.value <= hi:
        q = float(backend.ticks_to_rad(np.full(len(robot.joints), args.value))[k])
        raise SafetyError(
            f"servo id {args.id} (joint {robot.joint_names[k]}): goal position {args.value} ({q:+.3f} rad) is outside "
            f"robot {robot.name}'s joint limits, ticks [{lo}, {hi}] = [{robot.q_min_rad[k]:+.3f}, "
            f"{robot.q_max_rad[k]:+.3f}] rad; nothing written"
        )


#: With ``--robot``, ``servo write`` takes only these: the goal is checked against the joint's limits, torque on only
#: with a goal inside them near the present pose. Registers that move the limits, the zero, the mode, the speed
#: caps, the id or the baud rate are what the robot YAML and ``servo doctor`` manage; without ``--robot`` the
#: command is a raw register tool.
ROBOT_WRITABLE = frozenset({"GOAL_POSITION", "TORQUE_ENABLE", "LED"})


def _codec(wire: Wire, name: str) -> tuple[int | None, bool]:
    """``(sign bit, two's complement)`` of register ``name`` in ``wire``'s table: sign-magnitude registers (Feetech
    STS/SCS, Dynamixel Protocol 1.0 speeds and loads) and two's-complement ones (Dynamixel X); neither for a raw
    ``--addr``."""
    reg: Enum | None = wire.registers.__members__.get(name)
    if reg is None:
        return None, False
    return wire.sign_bits.get(reg), reg in wire.twos_complement


def _encode_value(wire: Wire, name: str, size: int, value: int) -> int:
    value = int(value)
    """The register bytes' value for ``value``, or InputError if it does not fit (a two's-complement -100 in a
    Feetech sign-magnitude register moved the zero by 171 degrees)."""
    from robogest.backends.servos.wire import sign_magnitude_encode

    bit, twos = _codec(wire, name)
    bits = 8 * size
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if twos else (0, (1 << bits) - 1)
    if bit is not None:
        lo, hi = -((1 << bit) - 1), (1 << bit) - 1
    if not lo <= value <= hi:
        raise InputError(f"{name}: value {value} does not fit the {size}-byte register (from {lo} to {hi})")
    if bit is not None:
        return sign_magnitude_encode(value, bit)
    return value & ((1 << bits) - 1)


def _decode_value(wire: Wire, name: str, size: int, raw: int) -> int:
    raw = int(raw)
    from robogest.backends.servos.wire import sign_magnitude_decode

    bit, twos = _codec(wire, name)
    if bit is not None:
        return sign_magnitude_decode(raw, bit)
    if twos and raw >= 1 << (8 * size - 1):
        return raw - (1 << (8 * size))
    return raw


def _read_value(link: Transport, sid: int, name: str) -> int:
    """Register ``name`` of servo ``sid``, decoded (:func:`_decode_value`)."""
    reg = link.wire.reg(name)
    return _decode_value(link.wire, name, reg.value[1], link.read(sid, reg))


def _check_robot_write(robot: RobotConfig, link: Transport, args: argparse.Namespace, name: str) -> None:
    """With ``--robot``: only :data:`ROBOT_WRITABLE`; a goal goes with the servo's speed cap and acceleration limit
    set from the joint's limits; torque on only with the goal inside the limits, near the present pose (a servo
    moved by hand while off would otherwise snap back to its old goal at full speed)."""
    if name not in ROBOT_WRITABLE:
        raise SafetyError(
            f"servo id {args.id}: with --robot, servo write takes only {', '.join(sorted(ROBOT_WRITABLE))}; {name} "
            "changes what the robot YAML and `robogest servo doctor` manage (limits, zero, mode, speed, id, baud); "
            "leave out --robot to write raw registers; nothing written"
        )
    if name == "LED" or (name == "TORQUE_ENABLE" and args.value == 0):
        return
    from robogest.backends.servos.check import require_hardware_safe

    require_hardware_safe(robot, "nothing written")  # the limits a goal is checked against must be the robot's
    backend, k = _joint_of_servo(robot, args)
    if name == "GOAL_POSITION":  # at the joint's speed and acceleration, as a session moves it, not the servo's top
        for reg, units in backend.profile_caps():
            if units[k]:  # 0: no acceleration register on this model (AX-12A, SCS0009)
                cap = link.wire.reg(reg.name)
                link.write(args.id, cap, _encode_value(link.wire, cap.name, cap.value[1], int(units[k])))
        return
    goal, present = (_read_value(link, args.id, r) for r in ("GOAL_POSITION", "PRESENT_POSITION"))
    goal_args = argparse.Namespace(id=args.id, value=goal, port=args.port)
    g_addr, g_size = link.wire.reg("GOAL_POSITION").value
    _check_goal_write(robot, goal_args, "GOAL_POSITION", g_addr, g_size, link.wire)
    if abs(goal - present) > TORQUE_ON_WITHIN_RAD * backend.models[k].ticks_per_rev / (2 * math.pi):
        raise SafetyError(
            f"servo id {args.id}: torque on would drive it from tick {present} to its goal {goal} at full speed; "
            f"write GOAL_POSITION {present} (where it is) first; nothing written"
        )


#: ``servo write --robot ... TORQUE_ENABLE 1`` needs the goal within this of the present position, radians.
TORQUE_ON_WITHIN_RAD = 0.05


def one(args: argparse.Namespace) -> int:
    """``servo ping``, ``servo read`` or ``servo write`` (see :func:`add_raw_parsers`)."""
    from robogest.backends.servos.protocol import ServoProtocol

    robot = _robot_of(args)
    protocol = ServoProtocol.named(args.protocol) if args.protocol else None
    if robot is not None and protocol is not None and protocol is not _robot_protocol(robot):
        raise InputError(
            f"--protocol {args.protocol} does not match robot {robot.name} ({_robot_protocol(robot).cli_name}); "
            "leave out --protocol to use the robot's"
        )
    protocol = protocol or (_robot_protocol(robot) if robot else ServoProtocol.DXL2)
    baud = args.baud or (robot.bus.baudrate if robot is not None and robot.bus is not None else 1_000_000)
    with _link(args.port, protocol, baud) as link:
        if not hasattr(args, "register"):
            # a Model Number read, not the SDK's ping: scservo_sdk's raises on a short or late reply
            model = link.read(args.id, link.wire.reg("MODEL_NUMBER"))
            print(f"id {args.id}: model {model} ({link.wire.model_named(model)})")
            return 0
        name, addr, size = _resolve(link, args)
        if hasattr(args, "value"):
            return _write_one(robot, link, args, name, addr, size)
        raw, err = link.read_at(args.id, addr, size, name, attempts=1)
        value = _decode_value(link.wire, name, size, raw)
        print(f"id {args.id}: {name} = {value}" + (f"  (error byte 0x{err:02X})" if err else ""))
        return 0


def _robot_of(args: argparse.Namespace) -> RobotConfig | None:
    """``--robot``'s config (``servo write`` only), which must have a bus section."""
    if not getattr(args, "robot", None):
        return None
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section; add one or leave out --robot")
    return robot


def _write_one(
    robot: RobotConfig | None, link: Transport, args: argparse.Namespace, name: str, addr: int, size: int
) -> int:
    """``servo write``: range-checked, checked against ``robot`` when given, an ID already taken refused."""
    raw = _encode_value(link.wire, name, size, args.value)
    if robot is not None:
        _check_goal_write(robot, args, name, addr, size, link.wire)
        _check_robot_write(robot, link, args, name)
    if name == "ID" and args.value != args.id and _answers(link, args.value):
        raise InputError(
            f"servo id {args.id}: id {args.value} is already taken on {args.port} (it answers); two servos "
            "with one id garble each other's replies; pick a free id (`robogest servo scan`); nothing written"
        )
    err = link.write_at(args.id, addr, size, raw, name, attempts=1)
    print(f"id {args.id}: wrote {args.value} to {name}; error byte 0x{err:02X} {link.ph.getRxPacketError(err)}")
    return 0 if not err else 5
