"""``robogest virtual-bus`` and ``robogest servo scan|doctor|calibrate|jog|ping|read|write|check``: bring-up."""

from __future__ import annotations

import argparse
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
        "servo", help="talk to servos directly: scan, doctor, calibrate, jog, ping, read, write, check"
    )
    ss = servo.add_subparsers(dest="servo_command", metavar="ACTION")
    scan = ss.add_parser(
        "scan", help="find every servo: broadcast ping per protocol and baud rate, the common ones first"
    )
    scan.add_argument("--port", required=True)
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
            epilog="With --robot, a write of the goal position outside that joint's limits is refused (exit 4) "
            "and nothing is written."
            if name == "write"
            else None,
        )
        p.add_argument("--port", required=True)
        p.add_argument("--id", type=checks.number(0, 253, integer=True), required=True, help="servo id, 0..253")
        robot_s = "the --robot's, else " if name == "write" else ""
        p.add_argument("--protocol", choices=_PROTOCOLS, default=None, help=f"default: {robot_s}dxl2")
        p.add_argument("--baud", type=checks.baud, default=None, help=f"default: {robot_s}1000000")
        if name == "write":
            p.add_argument("--robot", help="robot name or YAML path: goal positions are checked against its limits")
        if name != "ping":
            g = p.add_mutually_exclusive_group(required=True)
            g.add_argument("--register", help="register name, e.g. PRESENT_POSITION")
            g.add_argument("--addr", type=checks.number(0, 65535, integer=True), help="raw address (with --size)")
            p.add_argument("--size", type=int, choices=(1, 2, 4), default=None)
        if name == "write":
            p.add_argument("--value", type=checks.number(-(2**31), 2**32 - 1, integer=True), required=True)
        p.set_defaults(func=_one)
    add_check_parser(ss)
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
    return f"address {args.addr}", args.addr, args.size or 1


def _robot_protocol(robot: Any) -> str:
    """The ``--protocol`` name of a robot's bus."""
    bus = robot.bus
    if bus.family == "dynamixel":
        return "dxl2" if bus.protocol == 2.0 else "dxl1"
    return "sts" if bus.protocol == 0.0 else "scs"


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

    import robogest.backends.dynamixel
    import robogest.backends.feetech  # noqa: F401 - register the families
    from robogest.backends.base import get_backend_factory

    joints = {s.id: j for j, s in robot.bus.servos.items()}
    if args.id not in joints:
        raise InputError(f"servo id {args.id} is not in robot {robot.name} (ids {sorted(joints)}); check --id")
    backend = get_backend_factory(robot.bus.family)(robot, port=args.port)  # the mapping only; opens nothing
    k = robot.joint_names.index(joints[args.id])
    ends = backend.rad_to_ticks(robot.q_min_rad)[k], backend.rad_to_ticks(robot.q_max_rad)[k]
    lo, hi = int(min(ends)), int(max(ends))
    if not lo <= args.value <= hi:
        q = float(backend.ticks_to_rad(np.full(len(robot.joints), args.value))[k])
        raise SafetyError(
            f"servo id {args.id} (joint {joints[args.id]}): goal position {args.value} ({q:+.3f} rad) is outside "
            f"robot {robot.name}'s joint limits, ticks [{lo}, {hi}] = [{robot.q_min_rad[k]:+.3f}, "
            f"{robot.q_max_rad[k]:+.3f}] rad; nothing written"
        )


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
            if robot is not None:
                _check_goal_write(robot, args, name, addr, size, link.registers())
            fn = {1: ph.write1ByteTxRx, 2: ph.write2ByteTxRx, 4: ph.write4ByteTxRx}[size]
            comm, err = fn(port, args.id, addr, args.value)
            if not link.ok(comm):
                raise BackendError(f"servo id {args.id}: writing {name}: {ph.getTxRxResult(comm)}")
            print(f"id {args.id}: wrote {args.value} to {name}; error byte 0x{err:02X} {ph.getRxPacketError(err)}")
            return 0 if not err else 5
        fn = {1: ph.read1ByteTxRx, 2: ph.read2ByteTxRx, 4: ph.read4ByteTxRx}[size]
        value, comm, err = fn(port, args.id, addr)
        if not link.ok(comm):
            raise BackendError(f"servo id {args.id}: reading {name}: {ph.getTxRxResult(comm)}")
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
        bad = 0
        for k, name in enumerate(robot.joint_names):
            sid = int(backend.ids[k])
            h = backend.read_health(sid)
            inside = robot.q_min_rad[k] <= q[k] <= robot.q_max_rad[k]
            bad += not inside
            print(
                f"id {sid:3d} {name:16s} {backend.models[k].name:11s} q={q[k]:+.3f} rad "
                f"[{robot.q_min_rad[k]:+.2f}, {robot.q_max_rad[k]:+.2f}] {'ok' if inside else 'OUTSIDE LIMITS'}  "
                f"{h['temperature_c']:.0f} °C  {h['voltage_v']:.1f} V"
            )
        ok_temp = all(backend.read_health(int(i))["temperature_c"] <= backend.max_temperature_c for i in backend.ids)
        print("all servos present, models match" + ("" if bad == 0 else f"; {bad} joint(s) outside limits"))
        return 0 if bad == 0 and ok_temp and np.all(np.isfinite(q)) else 5
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
