"""``robogest virtual-bus`` and ``robogest servo scan|doctor|calibrate|jog|ping|read|write|check`` (``find-port`` and
``setup``: servo_setup_cmds): bring-up."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from typing import Any

from robogest.cli import checks
from robogest.cli.servo_raw_cmds import PROTOCOL_CHOICES
from robogest.errors import ConfigError, InputError


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
    scan.add_argument("--protocol", choices=PROTOCOL_CHOICES, action="append", help="repeatable; default all")
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
    doc.add_argument("--protocol", choices=PROTOCOL_CHOICES, action="append", help="without --robot: repeatable")
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
    from robogest.cli.servo_raw_cmds import add_raw_parsers

    add_raw_parsers(ss)
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


# --- scan ----------------------------------------------------------------------------------------
def _status(what: str, done: int, total: int) -> None:
    """Progress on a terminal: one line rewritten in place on stderr."""
    if sys.stderr.isatty():
        end = "\n" if done >= total else ""
        print(f"\r\033[Kscanning {what} ({done}/{total})", end=end, file=sys.stderr, flush=True)


def _scan(args: argparse.Namespace) -> int:
    import json

    from robogest.backends.servos.bringup import scan
    from robogest.backends.servos.protocol import ServoProtocol

    if args.robot is not None:
        return _scan_robot(args)
    if args.port is None:
        from robogest.cli.servo_setup_cmds import port_of

        args.port = port_of(None, None, "servo scan")
    protocols = [ServoProtocol.named(p) for p in args.protocol or []]
    found = scan(
        args.port, protocols, args.baud, max_id=args.max_id, per_id=args.per_id, all_protocols=args.all,
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

    from robogest.backends.servos.bringup import match_robot, scan_robot
    from robogest.backends.servos.protocol import ServoProtocol
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"{robot.path or robot.name}: no bus section, so no servos to look for; add one (README)")
    if args.protocol:
        raise InputError("servo scan --robot takes the protocol from the YAML's bus section; drop --protocol")
    from robogest.cli.servo_setup_cmds import port_of

    port = port_of(args.port, robot, "servo scan")
    proto = ServoProtocol.of_bus(robot.bus.family, robot.bus.protocol)
    bauds = args.baud or [robot.bus.baudrate]
    found = scan_robot(port, robot, bauds, max_id=args.max_id, per_id=args.per_id,
                       progress=lambda k, n, what: _status(what, k, n))  # fmt: skip
    rows = match_robot(robot, found)
    if args.json:
        print(json.dumps([r.as_dict() for r in rows], indent=1))
    else:
        print(f"{robot.name}: {proto.cli_name} at {', '.join(map(str, bauds))} baud on {port}")
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


def _check(args: argparse.Namespace) -> int:
    import numpy as np

    from robogest.backends.servos.bus import servo_backend
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    backend = servo_backend(robot, port=args.port, baudrate=args.baud)
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
