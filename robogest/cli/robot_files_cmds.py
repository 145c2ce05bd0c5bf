"""``robogest robots validate|import-urdf|import-lerobot-calibration``: bring your own robot and check it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from robogest.errors import ConfigError


def add_parsers(sub: Any) -> None:
    """Add the subcommands to ``robogest robots``."""
    p = sub.add_parser("validate", help="check a robot's YAML against its MuJoCo model, servos and retargeting")
    p.add_argument("robot", help="robot name or YAML path")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "import-urdf",
        help="make a robot from a URDF: MJCF with sites, servos, home keyframe and scene, plus a YAML to edit",
    )
    p.add_argument("urdf", type=Path, help="the robot's URDF (meshes: STL/OBJ next to or above it)")
    p.add_argument("--out", type=Path, required=True, help="robot YAML to write, e.g. robots/my_arm.yaml (the MJCF "
                   "goes to sim/NAME/ beside a robots/ folder, else to NAME/ beside the YAML)")  # fmt: skip
    p.add_argument("--name", help="robot name (default: the YAML file's name)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.set_defaults(func=cmd_import_urdf)

    p = sub.add_parser(
        "import-lerobot-calibration",
        help="servo zero offsets, directions and limits from a LeRobot calibration file, into a copy of a robot YAML",
    )
    p.add_argument(
        "calibration", type=Path, help="LeRobot calibration .json (~/.cache/huggingface/lerobot/calibration)"
    )
    p.add_argument("--robot", required=True, help="robot name or YAML path whose servos it calibrates")
    p.add_argument(
        "--out", type=Path, help="calibrated YAML to write (default: NAME_calibrated.yaml beside the robot's)"
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.set_defaults(func=cmd_import_lerobot_calibration)


def report_validation(name_or_path: str | Path) -> int:
    """Print every problem (file, key, fix) or one line saying the robot passed; ConfigError when any problem."""
    from robogest.robot.validate import validate

    problems = validate(name_or_path)
    for p in problems:
        print(p)
    if problems:
        raise ConfigError(f"robot {name_or_path}: {len(problems)} problem(s), listed above; fix them, then validate")
    print(f"{name_or_path}: valid (YAML, MuJoCo model, servos, home keyframe, retargeting)")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    return report_validation(args.robot)


def cmd_import_urdf(args: argparse.Namespace) -> int:
    from robogest.cli.checks import check_outputs
    from robogest.robot.urdf_import import import_urdf

    check_outputs({"--out": args.out}, {"URDF": args.urdf})
    res = import_urdf(args.urdf, args.out, name=args.name, overwrite=args.force)
    print(f"wrote {res.yaml_path}, {res.mjcf_path}, {res.scene_path}")
    print("guessed (edit the YAML and the MJCF to change it):")
    for g in res.guesses:
        print(f"  - {g}")
    return report_validation(res.yaml_path)


def cmd_import_lerobot_calibration(args: argparse.Namespace) -> int:
    from robogest.cli.checks import check_outputs
    from robogest.robot.lerobot_calibration import import_lerobot_calibration
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    check_outputs({"--out": args.out}, {"CALIBRATION": args.calibration, "--robot": robot.path})
    res = import_lerobot_calibration(args.calibration, robot, args.out, overwrite=args.force)
    print(f"wrote {res.path} (the original is unchanged)")
    for c in res.changes:
        print(f"  - {c}")
    return report_validation(res.path)
