"""``robogest robots list|show``: what robots exist and what exactly each one is (limits, mapping, servos)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.cli import checks
from robogest.cli.common import TextTable, add_json_flag, print_json, print_table, print_text, robot_files
from robogest.errors import ConfigError
from robogest.robot.registry import DEFAULT_ROBOT, find_robot, list_robots

if TYPE_CHECKING:  # imported lazily: `robogest --help` must not load rich, numpy or pydantic
    from robogest.robot.config import RobotConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("robots", help="list, show, validate or import robot definitions; check servos on a port")
    sub = p.add_subparsers(dest="robots_command", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])

    p_list = sub.add_parser("list", help="all robots found in $ROBOGEST_ROBOTS, ./robots and the packaged robots")
    add_json_flag(p_list)
    p_list.set_defaults(func=cmd_list)

    p_show = sub.add_parser("show", help="joints, limits, retargeting vectors and servos of one robot")
    p_show.add_argument("robot", nargs="?", default=DEFAULT_ROBOT, help=f"name or YAML path (default {DEFAULT_ROBOT})")
    p_show.add_argument("--render", metavar="PNG", type=Path, help="also render the robot at rest to this PNG")
    p_show.add_argument(
        "--size",
        type=checks.frame_size,
        default="640x480",
        help="--render size, WIDTHxHEIGHT (default 640x480)",
    )
    add_json_flag(p_show)
    p_show.set_defaults(func=cmd_show)

    from robogest.cli.servo_cmds import add_check_parser

    add_check_parser(sub)

    from robogest.cli.robot_files_cmds import add_parsers

    add_parsers(sub)


def cmd_list(args: argparse.Namespace) -> int:
    from rich.markup import escape

    table = TextTable("robots", ["name", "joints", "bus", "description"])
    entries = []
    for name, path in list_robots().items():
        entry = {"name": name, "file": str(path), "default": name == DEFAULT_ROBOT, "error": None}
        try:
            r = find_robot(str(path))
        except ConfigError as e:  # one broken YAML must not hide the others
            entry["error"] = str(e)
            last = str(e).splitlines()[-1].strip()
            table.rows.append([escape(name), "-", "-", f"[red]invalid:[/red] {escape(last)}"])
            entries.append(entry)
            continue
        entry.update(
            joints=len(r.joints),
            bus=r.bus.family if r.bus else None,
            servos=len(r.bus.servos) if r.bus else 0,
            description=r.description,
        )
        entries.append(entry)
        bus = f"{r.bus.family} ({len(r.bus.servos)} servos)" if r.bus else "-"
        default = " [dim](default)[/dim]" if entry["default"] else ""
        table.rows.append([escape(name) + default, str(len(r.joints)), bus, escape(r.description)])
    problems = [e["name"] for e in entries if e["error"]]
    if args.json:
        print_json(entries)
    else:
        print_table(table)
        if problems:
            print_text(f"[red]{len(problems)} invalid robot file(s)[/red]: run `robogest robots show NAME` for details")
    return 3 if problems else 0


def _deg(x: float) -> str:
    return f"{math.degrees(x):+.1f}"


def robot_as_dict(robot: RobotConfig) -> dict:
    """Everything ``robots show`` prints, as JSON-ready data (angles in radians, as in the YAML)."""
    return {"file": str(robot.path), "model_file": str(robot.model_path), **robot.model_dump(mode="json")}


def show_robot(robot: RobotConfig) -> None:
    """Print every table of ``robots show``."""
    from rich.markup import escape

    print_text(f"[bold]{escape(robot.name)}[/bold]  {escape(robot.description)}")
    print_text(escape(f"file: {robot.path}"))
    print_text(escape(f"model: {robot.model_path}"))

    cols = ["joint", "range deg", "range rad", "rest deg", "v max", "a max"]
    t = TextTable("joints (angles at the joint; v max in rad/s, a max in rad/s²)", cols, right_aligned=cols[1:])
    for j in robot.joints:
        t.rows.append(
            [
                j.name,
                f"{math.degrees(j.lower_rad):.1f}..{math.degrees(j.upper_rad):.1f}",
                f"{j.lower_rad:.3f}..{j.upper_rad:.3f}",
                _deg(j.rest_rad),
                f"{j.max_velocity_rad_s:.2f}",
                f"{j.max_acceleration_rad_s2:.1f}",
            ]
        )
    print_table(t)

    t = TextTable(
        "retargeting: human bone direction -> robot site vector",
        ["human from", "human to", "robot from", "robot to", "weight"],
    )
    for v in robot.retarget:
        t.rows.append([v.human[0], v.human[1], v.robot[0], v.robot[1], f"{v.weight:g}"])
    print_table(t)

    if robot.bus is None:
        print_text("bus: none (simulation only)")
        return
    b = robot.bus
    print_text(
        escape(
            f"bus: {b.family}, protocol {b.protocol:g}, {b.baudrate} baud, port {b.port or '(set on the command line)'}"
        )
    )
    t = TextTable(
        "servos: q_servo = direction * q_joint * gear + zero_offset",
        ["joint", "id", "model", "direction", "gear", "zero offset deg"],
    )
    for name, s in b.servos.items():
        t.rows.append([name, str(s.id), s.model, f"{s.direction:+d}", f"{s.gear_ratio:g}", _deg(s.zero_offset_rad)])
    print_table(t)


def cmd_show(args: argparse.Namespace) -> int:
    if args.render is not None:
        checks.check_outputs({"--render": args.render}, {"ROBOT": robot_files(args.robot)})
    robot = find_robot(args.robot)
    rendered = None
    if args.render is not None:
        from robogest.backends.render import render_png

        w, h = args.size
        rendered = render_png(robot, None, args.render, width=w, height=h)
    if args.json:
        print_json({**robot_as_dict(robot), "rendered": str(rendered) if rendered else None})
        return 0
    show_robot(robot)
    if rendered is not None:
        print(f"rendered rest pose to {rendered}")
    return 0
