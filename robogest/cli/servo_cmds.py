"""``robogest virtual-bus`` and ``robogest servo scan|ping|read|write|check``: hardware bring-up commands."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from typing import Any

from robogest.errors import BackendError, ConfigError, InputError, SafetyError

_DXL_BAUDS = (57600, 1_000_000, 115200, 2_000_000, 3_000_000, 4_000_000, 9600)
_FT_BAUDS = (1_000_000, 500_000, 115200, 57600, 38400, 19200)
_PROTOCOLS = ("dxl2", "dxl1", "sts", "scs")


def add_check_parser(sub: Any) -> None:
    """``check ROBOT --port PATH``; shared by ``robogest servo check`` and ``robogest robots check``."""
    check = sub.add_parser("check", help="check a robot's servos: ids, models, positions in limits, temperatures")
    check.add_argument("robot", help="robot name or YAML path")
    check.add_argument("--port", required=True, help="serial port of the servo bus")
    check.add_argument("--baud", type=int, default=None, help="baud rate (default: the robot YAML's bus.baudrate)")
    check.set_defaults(func=_check)


def register(subparsers: Any) -> None:
    vb = subparsers.add_parser("virtual-bus", help="serve a simulated servo bus on a pseudo-terminal")
    vb.add_argument("--robot", required=True, help="robot name or YAML path (needs a bus section)")
    vb.add_argument("--faults", default=None, help="fault spec, e.g. 'noreply=0.05,hwerror=3:overload@2.0'")
    vb.add_argument("--record", default=None, help="write the bus recording (.npz) here on exit")
    vb.set_defaults(func=_virtual_bus)

    servo = subparsers.add_parser("servo", help="talk to servos directly: scan, ping, read, write, check")
    ss = servo.add_subparsers(dest="servo_command", metavar="ACTION")
    scan = ss.add_parser("scan", help="broadcast-ping every protocol/baud (or the given ones)")
    scan.add_argument("--port", required=True)
    scan.add_argument("--protocol", choices=_PROTOCOLS, action="append", help="repeatable; default all")
    scan.add_argument("--baud", type=int, action="append", help="repeatable; default the common ones")
    scan.set_defaults(func=_scan)
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
        p.add_argument("--id", type=int, required=True)
        robot_s = "the --robot's, else " if name == "write" else ""
        p.add_argument("--protocol", choices=_PROTOCOLS, default=None, help=f"default: {robot_s}dxl2")
        p.add_argument("--baud", type=int, default=None, help=f"default: {robot_s}1000000")
        if name == "write":
            p.add_argument("--robot", help="robot name or YAML path: goal positions are checked against its limits")
        if name != "ping":
            g = p.add_mutually_exclusive_group(required=True)
            g.add_argument("--register", help="register name, e.g. PRESENT_POSITION")
            g.add_argument("--addr", type=int, help="raw address (with --size)")
            p.add_argument("--size", type=int, choices=(1, 2, 4), default=None)
        if name == "write":
            p.add_argument("--value", type=int, required=True)
        p.set_defaults(func=_one)
    add_check_parser(ss)
    servo.set_defaults(func=lambda a: (servo.print_help(), 2)[1])


# --- virtual-bus ---------------------------------------------------------------------------------
def _virtual_bus(args: argparse.Namespace) -> int:
    from robogest.robot.registry import find_robot
    from robogest.virtualbus import FaultSpec, VirtualBus

    robot = find_robot(args.robot)
    bus = VirtualBus(robot, FaultSpec.parse(args.faults))
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
class _Link:
    """A port opened with one vendor SDK for one protocol."""

    def __init__(self, port: str, protocol: str, baud: int) -> None:
        self.protocol = protocol
        if protocol.startswith("dxl"):
            import dynamixel_sdk as sdk

            self.ph = sdk.PacketHandler(2.0 if protocol == "dxl2" else 1.0)
        else:
            import scservo_sdk as sdk

            self.ph = sdk.PacketHandler(0 if protocol == "sts" else 1)
        self.sdk = sdk
        self.port = sdk.PortHandler(port)
        try:
            ok = self.port.openPort() and self.port.setBaudRate(baud)
        except Exception as e:
            raise BackendError(f"cannot open serial port {port}: {e}") from None
        if not ok:
            raise InputError(f"baud rate {baud} is not supported by the {protocol} SDK")

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.port.closePort()

    def registers(self) -> Any:
        from robogest.backends.dynamixel_tables import P1Reg, XReg
        from robogest.backends.feetech_tables import SCSReg, STSReg

        return {"dxl2": XReg, "dxl1": P1Reg, "sts": STSReg, "scs": SCSReg}[self.protocol]

    def ok(self, comm: int) -> bool:
        return comm == self.sdk.COMM_SUCCESS

    def model_name(self, number: int) -> str:
        from robogest.backends.dynamixel_tables import MODELS as DM
        from robogest.backends.feetech_tables import MODELS as FM

        for m in (*DM.values(), *FM.values()):
            if m.number == number:
                return m.name
        return "?"


def _scan(args: argparse.Namespace) -> int:
    protocols = args.protocol or list(_PROTOCOLS)
    found_any = False
    for proto in protocols:
        bauds = args.baud or (_DXL_BAUDS if proto.startswith("dxl") else _FT_BAUDS)
        for baud in bauds:
            link = _Link(args.port, proto, baud)
            try:
                rows = _scan_one(link)
            finally:
                link.close()
            for sid, model, fw in rows:
                found_any = True
                name = link.model_name(model)
                print(f"{proto:5s} {baud:8d} baud  id {sid:3d}  model {model:5d} ({name})  firmware {fw}")
    if not found_any:
        print(f"no servo answered on {args.port}", file=sys.stderr)
        return 1
    return 0


def _scan_one(link: _Link) -> list[tuple[int, int, int]]:
    if link.protocol == "dxl2":
        data, comm = link.ph.broadcastPing(link.port)
        return [(sid, v[0], v[1]) for sid, v in sorted(data.items())] if link.ok(comm) else []
    rows = []
    fw_addr = 2 if link.protocol == "dxl1" else 0
    for sid in range(0, 253):
        model, comm, _ = link.ph.ping(link.port, sid)
        if link.ok(comm):
            fw, _, _ = link.ph.read1ByteTxRx(link.port, sid, fw_addr)
            rows.append((sid, model, fw))
    return rows


def _resolve(link: _Link, args: argparse.Namespace) -> tuple[str, int, int]:
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
    link = _Link(args.port, protocol, baud)
    try:
        ph, port = link.ph, link.port
        if args.func is _one and not hasattr(args, "register"):
            model, comm, err = ph.ping(port, args.id)
            if not link.ok(comm):
                raise BackendError(f"servo id {args.id}: no answer to ping ({ph.getTxRxResult(comm)})")
            print(f"id {args.id}: model {model} ({link.model_name(model)}), error byte 0x{err:02X}")
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
