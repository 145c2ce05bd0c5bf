"""``robogest robots list|show``: what robots exist and what exactly each one is (limits, mapping, servos)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.errors import ConfigError
from robogest.robot.registry import DEFAULT_ROBOT, find_robot, list_robots

if TYPE_CHECKING:  # imported lazily: `robogest --help` must not load rich, numpy or pydantic
    from rich.console import Console

    from robogest.robot.config import RobotConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("robots", help="list robot definitions, show one, or check its servos on a port")
    sub = p.add_subparsers(dest="robots_command", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])

    p_list = sub.add_parser("list", help="all robots found in $ROBOGEST_ROBOTS and robots/")
    p_list.set_defaults(func=cmd_list)

    p_show = sub.add_parser("show", help="joints, limits, retargeting vectors and servos of one robot")
    p_show.add_argument("robot", nargs="?", default=DEFAULT_ROBOT, help=f"name or YAML path (default {DEFAULT_ROBOT})")
    p_show.add_argument("--render", metavar="PNG", type=Path, help="also render the robot at rest to this PNG")
    p_show.add_argument("--size", default="640x480", help="image size for --render, WIDTHxHEIGHT (default 640x480)")
    p_show.set_defaults(func=cmd_show)

    from robogest.cli.servo_cmds import add_check_parser

    add_check_parser(sub)


def cmd_list(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    table = Table(title="robots", show_lines=False)
    table.add_column("name", no_wrap=True)
    for col in ("joints", "bus", "description"):
        table.add_column(col)
    problems = []
    for name, path in list_robots().items():
        try:
            r = find_robot(str(path))
        except ConfigError as e:  # one broken YAML must not hide the others
            table.add_row(name, "-", "-", f"[red]invalid:[/red] {str(e).splitlines()[-1].strip()}")
            problems.append(name)
            continue
        bus = f"{r.bus.family} ({len(r.bus.servos)} servos)" if r.bus else "-"
        default = " [dim](default)[/dim]" if name == DEFAULT_ROBOT else ""
        table.add_row(name + default, str(len(r.joints)), bus, r.description)
    console.print(table)
    if problems:
        console.print(f"[red]{len(problems)} invalid robot file(s)[/red]: run `robogest robots show NAME` for details")
        return 3
    return 0


def _deg(x: float) -> str:
    return f"{math.degrees(x):+.1f}"


def show_robot(robot: RobotConfig, console: Console) -> None:
    """Print every table of ``robots show``."""
    from rich import box
    from rich.table import Table

    console.print(f"[bold]{robot.name}[/bold]  {robot.description}")
    console.print(f"file: {robot.path}\nmodel: {robot.model_path}")

    t = Table(title="joints (angles at the joint; v max in rad/s, a max in rad/s²)", box=box.SIMPLE_HEAD)
    t.add_column("joint", no_wrap=True)
    for col in ("range deg", "range rad", "rest deg", "v max", "a max"):
        t.add_column(col, justify="right", no_wrap=True)
    for j in robot.joints:
        t.add_row(
            j.name,
            f"{math.degrees(j.lower_rad):.1f}..{math.degrees(j.upper_rad):.1f}",
            f"{j.lower_rad:.3f}..{j.upper_rad:.3f}",
            _deg(j.rest_rad),
            f"{j.max_velocity_rad_s:.2f}",
            f"{j.max_acceleration_rad_s2:.1f}",
        )
    console.print(t)

    t = Table(title="retargeting: human bone direction -> robot site vector")
    for col in ("human from", "human to", "robot from", "robot to", "weight"):
        t.add_column(col)
    for v in robot.retarget:
        t.add_row(v.human[0], v.human[1], v.robot[0], v.robot[1], f"{v.weight:g}")
    console.print(t)

    if robot.bus is None:
        console.print("bus: none (simulation only)")
        return
    b = robot.bus
    console.print(
        f"bus: {b.family}, protocol {b.protocol:g}, {b.baudrate} baud, port {b.port or '(set on the command line)'}"
    )
    t = Table(title="servos: q_servo = direction * q_joint * gear + zero_offset")
    for col in ("joint", "id", "model", "direction", "gear", "zero offset deg"):
        t.add_column(col)
    for name, s in b.servos.items():
        t.add_row(name, str(s.id), s.model, f"{s.direction:+d}", f"{s.gear_ratio:g}", _deg(s.zero_offset_rad))
    console.print(t)


def _parse_size(text: str) -> tuple[int, int]:
    from robogest.errors import InputError

    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    return w, h


def cmd_show(args: argparse.Namespace) -> int:
    from rich.console import Console

    robot = find_robot(args.robot)
    console = Console()
    show_robot(robot, console)
    if args.render is not None:
        from robogest.backends.render import render_png

        w, h = _parse_size(args.size)
        out = render_png(robot, None, args.render, width=w, height=h)
        console.print(f"rendered rest pose to {out}")
    return 0
