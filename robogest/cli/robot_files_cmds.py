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
