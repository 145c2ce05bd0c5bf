"""``robogest virtual-bus`` and ``robogest servo scan|doctor|calibrate|jog|ping|read|write|check`` (``find-port`` and
``setup``: servo_setup_cmds): bring-up."""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
from typing import Any

from robogest.cli import checks
from robogest.errors import BackendError, ConfigError, InputError, SafetyError

_PROTOCOLS = ("dxl2", "sts", "scs", "dxl1")


def add_check_parser(sub: Any) -> None:
    """``check ROBOT --port PATH``; shared by ``robogest servo check`` and ``robogest robots check``."""
    check = sub.add_parser("check", help="check a robot's servos: ids, models, positions in limits, temperatures")
    check.add_argument("robot", help="robot name or YAML path")
    check.add_argument("--port", required=True, help="serial port of the servo bus")
    check.add_argument(
        "--baud", type=checks.baud, default=None, help="baud rate (default: the robot YAML's bus.baudrate)"
    )
    check.set_defaults(func=_check)


def register(subparsers: Any) -> None:
    vb = subparsers.add_parser("virtual-bus", help="serve a simulated servo bus on a pseudo-terminal")
    vb.add_argument("--robot", required=True, help="robot name or YAML path (needs a bus section)")
    vb.add_argument("--faults", default=None, help="fault spec, e.g. 'noreply=0.05,hwerror=3:overload@2.0'")
    vb.add_argument("--record", default=None, help="write the bus recording (.npz) here on exit")
    vb.add_argument(
        "--return-delay-time", type=int, default=0,
        help="Return Delay Time of every servo, 2 us units (default: 0; -1: each model's factory value)",
    )  # fmt: skip
    vb.set_defaults(func=_virtual_bus)

    servo = subparsers.add_parser(
        "servo",
        help="talk to servos directly: find-port, setup, scan, doctor, calibrate, jog, ping, read, write, check",
    )
    ss = servo.add_subparsers(dest="servo_command", metavar="ACTION")
    scan = ss.add_parser(
        "scan",
        help="find every servo: broadcast ping per protocol and baud rate, the common ones first; with --robot, "
        "each joint's expected id and model against what answers",
        description="Without --robot: every servo on the port, at every protocol and baud rate (common ones first). "
        "With --robot NAME|PATH: at the YAML's bus protocol and baud rate, one row per joint, the id and model "
        "its bus.servos entry expects against what answers there (ok, MISSING, WRONG MODEL), then any id that "
        "answers but no joint has (UNEXPECTED); exit code 5 unless every row is ok. For wiring and numbering "
        "servos with the YAML in hand.",
    )
    scan.add_argument("--port", help="serial port (default: the --robot YAML's bus.port, else the one USB serial port)")
    scan.add_argument("--robot", help="robot name or YAML path: compare the bus with its bus section")
    scan.add_argument("--protocol", choices=_PROTOCOLS, action="append", help="repeatable; default all")
    scan.add_argument("--baud", type=checks.baud, action="append", help="repeatable; default the common ones")
    scan.add_argument(
        "--max-id",
        type=checks.number(0, 252, integer=True),
        default=252,
        help="highest id to wait for (default: %(default)s)",
    )
    scan.add_argument("--per-id", action="store_true", help="ask ids one by one (servos that ignore broadcasts)")
    scan.add_argument("--all", action="store_true", help="try every protocol, not only up to the first that answers")
    scan.add_argument("--json", action="store_true", help="print a JSON list instead of one line per servo")
    scan.set_defaults(func=_scan)
    doc = ss.add_parser(
        "doctor",
        help="check (and with --fix, set) what breaks real buses: latency timer, return delay, baud, limits, power",
    )
    doc.add_argument("--port", required=True)
    doc.add_argument("--robot", help="robot name or YAML: also check ids, baud and position limits against it")
    doc.add_argument("--protocol", choices=_PROTOCOLS, action="append", help="without --robot: repeatable")
    doc.add_argument("--baud", type=checks.baud, action="append", help="without --robot: repeatable")
    doc.add_argument("--fix", action="store_true", help="set what can be set (turns torque off: support the arms)")
    doc.set_defaults(func=_doctor)
    cal = ss.add_parser(
        "calibrate",
        help="torque off, you move each joint to its zero pose and both ends; writes a calibrated copy of the YAML",
    )
    cal.add_argument("--robot", required=True, help="robot name or YAML path")
    cal.add_argument("--port", default=None, help="serial port (default: the YAML's bus.port)")
    cal.add_argument("--out", default=None, help="output YAML (default: NAME.calibrated.yaml beside the original)")
    cal.add_argument("--joint", action="append", help="calibrate only these joints (repeatable)")
    cal.add_argument("--margin-rad", type=float, default=0.05, help="kept inside each measured end (default: 0.05)")
    cal.set_defaults(func=_calibrate)
    jog = ss.add_parser(
        "jog", help="move one joint to an angle within its limits, gently; then back to rest and torque off"
    )
    jog.add_argument("--robot", required=True, help="robot name or YAML path")
    jog.add_argument("joint", help="joint name")
    jog.add_argument("angle", type=float, help="target angle, radians (must lie within the joint's limits)")
    jog.add_argument("--port", default=None, help="serial port (default: the YAML's bus.port)")
    jog.add_argument("--speed", type=float, default=0.25, help="fraction of the joint's speed limit (default: 0.25)")
    jog.add_argument("--hold", type=float, default=1.0, help="seconds to hold the angle (default: %(default)s)")
    jog.set_defaults(func=_jog)
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
        p.add_argument("--protocol", choices=_PROTOCOLS, default=None, help=f"default: {robot_s}dxl2")
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
        p.set_defaults(func=_one)
    add_check_parser(ss)
    from robogest.cli.servo_setup_cmds import add_parsers

    add_parsers(ss)
    servo.set_defaults(func=lambda a: (servo.print_help(), 2)[1])


# --- virtual-bus ---------------------------------------------------------------------------------
def _virtual_bus(args: argparse.Namespace) -> int:
    from robogest.cli.checks import check_outputs
    from robogest.robot.registry import find_robot
    from robogest.virtualbus import FaultSpec, VirtualBus

    check_outputs({"--record": args.record}, {"--robot": args.robot if os.path.isfile(args.robot) else None})
    robot = find_robot(args.robot)
    rdt = None if args.return_delay_time < 0 else args.return_delay_time
    if rdt is not None and rdt > 254:
        raise InputError(f"--return-delay-time {rdt} is out of range; use 0..254, or -1 for the factory value")
    bus = VirtualBus(robot, FaultSpec.parse(args.faults), return_delay_time=rdt)
    stop = threading.Event()
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    bus.start()
    try:
        print(bus.port, flush=True)
        print(
            f"serving {robot.name}: {len(bus.servos)} {bus.family} servos, protocol {bus.protocol:g}, "
            f"faults: {bus.faults}; Ctrl-C to stop",
            file=sys.stderr,
            flush=True,
        )
        while not stop.wait(0.2):
            if bus.disconnected:
                print("port disconnected (injected fault); waiting for Ctrl-C", file=sys.stderr, flush=True)
                stop.wait()
    finally:
        bus.stop()
        for s, h in old.items():
            signal.signal(s, h)
        if args.record:
            path = bus.save_record(args.record)
            print(f"recording written to {path}", file=sys.stderr)
    return 0


# --- raw access ----------------------------------------------------------------------------------
def _link(port: str, protocol: str, baud: int) -> Any:
    from robogest.backends.bringup import ServoLink

    return ServoLink(port, protocol, baud)


def _status(what: str, done: int, total: int) -> None:
    """Progress on a terminal: one line rewritten in place on stderr."""
    if sys.stderr.isatty():
        end = "\n" if done >= total else ""
        print(f"\r\033[Kscanning {what} ({done}/{total})", end=end, file=sys.stderr, flush=True)


def _scan(args: argparse.Namespace) -> int:
    import json

    from robogest.backends.bringup import scan

    if args.robot is not None:
        return _scan_robot(args)
    if args.port is None:
        from robogest.cli.servo_setup_cmds import port_of

        args.port = port_of(None, None, "servo scan")
    found = scan(
        args.port, args.protocol, args.baud, max_id=args.max_id, per_id=args.per_id, all_protocols=args.all,
        progress=lambda k, n, what: _status(what, k, n),
    )  # fmt: skip
    if args.json:
        print(json.dumps([f.as_dict() for f in found], indent=1))
    else:
        for f in found:
            print(f.line())
    if not found:
        print(f"no servo answered on {args.port} (check power and wiring; try --per-id)", file=sys.stderr)
        return 1
    return 0


def _scan_robot(args: argparse.Namespace) -> int:
    """``servo scan --robot``: the robot's bus section against what answers (see the subcommand's description)."""
    import json

    from robogest.backends.bringup import match_robot, protocol_name, scan_robot
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"{robot.path or robot.name}: no bus section, so no servos to look for; add one (README)")
    if args.protocol:
        raise InputError("servo scan --robot takes the protocol from the YAML's bus section; drop --protocol")
    from robogest.cli.servo_setup_cmds import port_of

    port = port_of(args.port, robot, "servo scan")
    proto = protocol_name(robot.bus.family, robot.bus.protocol)
    bauds = args.baud or [robot.bus.baudrate]
    found = scan_robot(port, robot, bauds, max_id=args.max_id, per_id=args.per_id,
                       progress=lambda k, n, what: _status(what, k, n))  # fmt: skip
    rows = match_robot(robot, found)
    if args.json:
        print(json.dumps([r.as_dict() for r in rows], indent=1))
    else:
        print(f"{robot.name}: {proto} at {', '.join(map(str, bauds))} baud on {port}")
        for r in rows:
            print(r.line())
    bad = [r for r in rows if not r.ok]
    if bad:
        hint = " (none answered: check power, wiring and the baud rate; `robogest servo scan --port` tries all)"
        print(f"{len(bad)} of {len(rows)} rows differ from {robot.path or robot.name}" + (hint if not found else ""),
              file=sys.stderr)  # fmt: skip
        return 5
    print(f"all {len(rows)} servos answer with the ids and models the YAML expects")
    return 0


def _answers(link: Any, sid: int) -> bool:
    """Whether a servo answers at id ``sid`` (its Model Number is read)."""
    try:
        link.read(sid, link.reg("MODEL_NUMBER"), attempts=2)
    except BackendError:
        return False
    return True


def _resolve(link: Any, args: argparse.Namespace) -> tuple[str, int, int]:
    if args.register:
        regs = link.registers()
        key = args.register.upper()
        if key not in regs.__members__:
            raise InputError(
                f"unknown register {args.register!r} for {link.protocol}; one of {', '.join(regs.__members__)}"
            )
        addr, size = regs[key].value
        return key, addr, size
    if args.size is None:  # a 1-byte default read the low byte of a 4-byte register, and wrote it alone
        raise InputError(f"--addr {args.addr} needs --size 1, 2 or 4 (the register's width in bytes), or --register")
    return f"address {args.addr}", args.addr, args.size


def _robot_protocol(robot: Any) -> str:
    """The ``--protocol`` name of a robot's bus."""
    bus = robot.bus
    if bus.family == "dynamixel":
        return "dxl2" if bus.protocol == 2.0 else "dxl1"
    return "sts" if bus.protocol == 0.0 else "scs"


def _joint_of_servo(robot: Any, args: argparse.Namespace) -> tuple[Any, int]:
    """``(backend, k)``: the robot's backend (its rad/tick mapping only; opens nothing) and the index of the joint
    that servo ``args.id`` moves."""
    import robogest.backends.dynamixel
    import robogest.backends.feetech  # noqa: F401 - register the families
    from robogest.backends.base import get_backend_factory

    joints = {s.id: j for j, s in robot.bus.servos.items()}
    if args.id not in joints:
        raise InputError(f"servo id {args.id} is not in robot {robot.name} (ids {sorted(joints)}); check --id")
    return get_backend_factory(robot.bus.family)(robot, port=args.port), robot.joint_names.index(joints[args.id])


def _check_goal_write(robot: Any, args: argparse.Namespace, name: str, addr: int, size: int, regs: Any) -> None:
    """Refuse (nothing written) a goal-position write outside the joint limits of the servo's joint in ``robot``."""
    g_addr, g_size = regs.GOAL_POSITION.value
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


def _value_codec(protocol: str, name: str) -> tuple[int | None, bool]:
    """``(sign bit, two's complement)`` of register ``name``: sign-magnitude registers (Feetech STS/SCS, Dynamixel
    Protocol 1.0 speeds and loads) and two's-complement ones (Dynamixel X)."""
    from robogest.backends import dynamixel_tables as dt
    from robogest.backends import feetech_tables as ft

    signs = {"sts": ft.STS_SIGN_BITS, "scs": ft.SCS_SIGN_BITS, "dxl1": dt.P1_SIGN_BITS}.get(protocol, {})
    bit = next((b for r, b in signs.items() if r.name == name), None)
    return bit, protocol == "dxl2" and any(r.name == name for r in dt.X_SIGNED)


def _encode_value(protocol: str, name: str, size: int, value: int) -> int:
    """The register bytes' value for ``value``, or InputError if it does not fit (a two's-complement -100 in a
    Feetech sign-magnitude register moved the zero by 171 degrees)."""
    from robogest.backends.servo_common import sign_magnitude_encode

    bit, twos = _value_codec(protocol, name)
    bits = 8 * size
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if twos else (0, 2**bits - 1)
    if bit is not None:
        lo, hi = -(2**bit - 1), 2**bit - 1
    if not lo <= value <= hi:
        raise InputError(f"{name}: value {value} does not fit the {size}-byte register (from {lo} to {hi})")
    if bit is not None:
        return sign_magnitude_encode(value, bit)
    return value & (2**bits - 1)


def _decode_value(protocol: str, name: str, size: int, raw: int) -> int:
    from robogest.backends.servo_common import sign_magnitude_decode

    bit, twos = _value_codec(protocol, name)
    if bit is not None:
        return sign_magnitude_decode(raw, bit)
    if twos and raw >= 2 ** (8 * size - 1):
        return raw - 2 ** (8 * size)
    return raw


def _read_value(link: Any, sid: int, name: str) -> int:
    """Register ``name`` of servo ``sid``, decoded (:func:`_decode_value`)."""
    reg = link.reg(name)
    return _decode_value(link.protocol, name, reg.value[1], link.read(sid, reg))


def _check_robot_write(robot: Any, link: Any, args: argparse.Namespace, name: str) -> None:
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
    from robogest.backends.servo_check import require_hardware_safe

    require_hardware_safe(robot, "nothing written")  # the limits a goal is checked against must be the robot's
    backend, k = _joint_of_servo(robot, args)
    if name == "GOAL_POSITION":  # at the joint's speed and acceleration, as a session moves it, not the servo's top
        for reg, units in backend.profile_caps():
            if units[k]:  # 0: no acceleration register on this model (AX-12A, SCS0009)
                cap = link.reg(reg.name)
                link.write(args.id, cap, _encode_value(link.protocol, cap.name, cap.value[1], int(units[k])))
        return
    goal, present = (_read_value(link, args.id, r) for r in ("GOAL_POSITION", "PRESENT_POSITION"))
    goal_args = argparse.Namespace(id=args.id, value=goal, port=args.port)
    _check_goal_write(robot, goal_args, "GOAL_POSITION", *link.reg("GOAL_POSITION").value, link.registers())
    if abs(goal - present) > TORQUE_ON_WITHIN_RAD * backend.models[k].ticks_per_rev / (2 * math.pi):
        raise SafetyError(
            f"servo id {args.id}: torque on would drive it from tick {present} to its goal {goal} at full speed; "
            f"write GOAL_POSITION {present} (where it is) first; nothing written"
        )


#: ``servo write --robot ... TORQUE_ENABLE 1`` needs the goal within this of the present position, radians.
TORQUE_ON_WITHIN_RAD = 0.05


def _one(args: argparse.Namespace) -> int:
    robot = None
    if getattr(args, "robot", None):
        from robogest.robot.registry import find_robot

        robot = find_robot(args.robot)
        if robot.bus is None:
            raise ConfigError(f"robot {robot.name!r} has no bus section; add one or leave out --robot")
        if args.protocol and args.protocol != _robot_protocol(robot):
            raise InputError(
                f"--protocol {args.protocol} does not match robot {robot.name} ({_robot_protocol(robot)}); "
                "leave out --protocol to use the robot's"
            )
    protocol = args.protocol or (_robot_protocol(robot) if robot else "dxl2")
    baud = args.baud or (robot.bus.baudrate if robot else 1_000_000)
    link = _link(args.port, protocol, baud)
    try:
        ph, port = link.ph, link.port
        if args.func is _one and not hasattr(args, "register"):
            # a Model Number read, not the SDK's ping: scservo_sdk's raises on a short or late reply
            model = link.read(args.id, link.reg("MODEL_NUMBER"))
            print(f"id {args.id}: model {model} ({link.model_name(model)})")
            return 0
        name, addr, size = _resolve(link, args)
        if hasattr(args, "value"):
            raw = _encode_value(protocol, name, size, args.value)
            if robot is not None:
                _check_goal_write(robot, args, name, addr, size, link.registers())
                _check_robot_write(robot, link, args, name)
            if name == "ID" and args.value != args.id and _answers(link, args.value):
                raise InputError(
                    f"servo id {args.id}: id {args.value} is already taken on {args.port} (it answers); two servos "
                    "with one id garble each other's replies; pick a free id (`robogest servo scan`); nothing written"
                )
            fn = {1: ph.write1ByteTxRx, 2: ph.write2ByteTxRx, 4: ph.write4ByteTxRx}[size]
            comm, err = fn(port, args.id, addr, raw)
            if not link.ok(comm):
                raise BackendError(f"servo id {args.id}: writing {name}: {ph.getTxRxResult(comm)}")
            print(f"id {args.id}: wrote {args.value} to {name}; error byte 0x{err:02X} {ph.getRxPacketError(err)}")
            return 0 if not err else 5
        fn = {1: ph.read1ByteTxRx, 2: ph.read2ByteTxRx, 4: ph.read4ByteTxRx}[size]
        value, comm, err = fn(port, args.id, addr)
        if not link.ok(comm):
            raise BackendError(f"servo id {args.id}: reading {name}: {ph.getTxRxResult(comm)}")
        value = _decode_value(protocol, name, size, value)
        print(f"id {args.id}: {name} = {value}" + (f"  (error byte 0x{err:02X})" if err else ""))
        return 0
    finally:
        link.close()


def _check(args: argparse.Namespace) -> int:
    import numpy as np

    import robogest.backends.dynamixel
    import robogest.backends.feetech  # noqa: F401
    from robogest.backends.base import get_backend_factory
    from robogest.errors import ConfigError
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section")
    backend = get_backend_factory(robot.bus.family)(robot, port=args.port, baudrate=args.baud)
    backend.connect()  # pings ids, checks models; raises naming the servo
    try:
        q = backend.read_positions()
        bad = hot = volts = 0
        for k, name in enumerate(robot.joint_names):
            sid = int(backend.ids[k])
            h = backend.read_health(sid)
            lo_v, hi_v = backend._volt_limits.get(sid, (0.0, float("inf")))
            inside = robot.q_min_rad[k] <= q[k] <= robot.q_max_rad[k]
            too_hot = h["temperature_c"] > backend.max_temperature_c
            off_volts = not lo_v <= h["voltage_v"] <= hi_v
            bad, hot, volts = bad + (not inside), hot + too_hot, volts + off_volts
            flags = [] if inside else ["OUTSIDE LIMITS"]
            flags += [f"TOO HOT (limit {backend.max_temperature_c:.0f} °C)"] if too_hot else []
            flags += [f"SUPPLY OUTSIDE [{lo_v:.1f}, {hi_v:.1f}] V"] if off_volts else []
            print(
                f"id {sid:3d} {name:16s} {backend.models[k].name:11s} q={q[k]:+.3f} rad "
                f"[{robot.q_min_rad[k]:+.2f}, {robot.q_max_rad[k]:+.2f}] {', '.join(flags) or 'ok'}  "
                f"{h['temperature_c']:.0f} °C  {h['voltage_v']:.1f} V"
            )
        counts = ((bad, "joint(s) outside limits"), (hot, "servo(s) too hot"),
                  (volts, "servo(s) with the supply outside their range"))  # fmt: skip
        problems = [f"{n} {what}" for n, what in counts if n]
        print("all servos present, models match" + "".join(f"; {p}" for p in problems))
        return 0 if not problems and np.all(np.isfinite(q)) else 5
    finally:
        backend.disconnect()


def _doctor(args: argparse.Namespace) -> int:
    from robogest.cli.servo_bringup_cmds import doctor

    return doctor(args)


def _calibrate(args: argparse.Namespace) -> int:
    from robogest.cli.servo_bringup_cmds import calibrate

    return calibrate(args)


def _jog(args: argparse.Namespace) -> int:
    from robogest.cli.servo_bringup_cmds import jog

    return jog(args)
