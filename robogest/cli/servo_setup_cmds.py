"""``robogest servo find-port|setup``: which serial port is the robot's, and each servo's id and baud rate from the
robot YAML, one servo at a time (robogest.backends.servos.setup; docs/servos.md)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from robogest.cli import checks
from robogest.errors import ConfigError, InputError

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig


def add_parsers(ss: Any) -> None:
    """Add ``find-port`` and ``setup`` to ``robogest servo``."""
    fp = ss.add_parser(
        "find-port",
        help="list serial ports, then find the robot's: unplug its USB adapter when asked, the port that vanished "
        "is the one",
    )
    fp.add_argument("--list", action="store_true", help="only list the serial ports (no questions)")
    fp.set_defaults(func=find_port)
    su = ss.add_parser(
        "setup",
        help="connect one servo at a time, as asked: each gets its id and baud rate from the robot YAML (torque "
        "stays off)",
        description="For new servos (all with the factory id) or a rewired robot: in the order of the YAML's joints, "
        "asks you to connect ONLY that joint's servo, finds it at any id and baud rate, writes the id and baud rate "
        "its bus section gives, and checks them. Ctrl-C leaves the servo being written with its old or its new "
        "settings (never half) and says which; --joint continues from there.",
    )
    su.add_argument("--robot", required=True, help="robot name or YAML path (its bus section)")
    su.add_argument(
        "--port", help="serial port (default: the YAML's bus.port, else the one USB serial port plugged in)"
    )
    su.add_argument("--joint", action="append", help="set up only these joints' servos (repeatable)")
    su.add_argument(
        "--max-id",
        type=checks.number(0, 252, integer=True),
        default=252,
        help="highest id a servo may have now (default: %(default)s)",
    )
    su.set_defaults(func=setup)


def _ask(prompt: str) -> str:
    """One answer through input(); a closed stdin is one line, not a traceback."""
    try:
        return input(prompt)
    except EOFError:
        print(file=sys.stderr)
        raise InputError("this command asks questions: run it in a terminal (stdin was closed)") from None


def _say(line: str) -> None:
    print(line, flush=True)


def find_port(args: argparse.Namespace) -> int:
    from robogest.backends.servos import setup as servo_setup

    if args.list:
        ports = servo_setup.list_ports()
        for p in ports:
            print(p.line())
        if not ports:
            print("no serial port found; plug in the servo adapter's USB cable", file=sys.stderr)
        return 0 if ports else 5
    servo_setup.find_port(_ask, _say, servo_setup.list_ports)
    return 0


def port_of(port: str | None, robot: RobotConfig | None, what: str) -> str:
    """``--port``, else the robot's ``bus.port``, else the one USB serial port (InputError listing them)."""
    from robogest.backends.servos import setup as servo_setup

    if port:
        return port
    if robot is not None and robot.bus is not None and robot.bus.port:
        return str(robot.bus.port)
    found = servo_setup.the_one_port(servo_setup.list_ports, what)
    print(f"using {found}, the one USB serial port plugged in", file=sys.stderr)
    return found


def setup(args: argparse.Namespace) -> int:
    from robogest.backends.servos import setup as servo_setup
    from robogest.cli.servo_cmds import _status
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"{robot.path or robot.name}: no bus section, so no servo ids to write; add one")
    servo_setup.targets(robot, args.joint)  # a bad --joint or baud rate: refused before any question
    port = port_of(args.port, robot, "servo setup")
    print(f"{robot.name}: {len(args.joint or robot.joint_names)} servo(s) on {port}; torque stays off", flush=True)
    done = servo_setup.setup_servos(port, robot, _ask, _say, joints=args.joint, max_id=args.max_id,
                                    progress=lambda k, n, what: _status(what, k, n))  # fmt: skip
    print(f"{len(done)} servo(s) set up; connect them all, then check: robogest servo scan --robot {args.robot} "
          f"--port {port}")  # fmt: skip
    return 0
