"""``robogest robots validate|import|import-lerobot-calibration``: bring your own robot and check it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.errors import ConfigError

if TYPE_CHECKING:
    from robogest.tools.importer.parts import Parts


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the subcommands to ``robogest robots``."""
    p = sub.add_parser("validate", help="check a robot's YAML against its MuJoCo model, servos and retargeting")
    p.add_argument("robot", help="robot name or YAML path")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "import",
        aliases=["import-urdf"],
        help="make a robot from a URDF, xacro or MJCF description: MJCF with sites, servos, home keyframe and "
        "scene, plus a YAML with held joints to edit",
    )
    p.add_argument(
        "description",
        type=Path,
        metavar="FILE",
        help="the robot's URDF, xacro (.xacro) or MJCF (.xml); meshes STL/OBJ/DAE in its folders (xacro and DAE "
        "need the import extra)",
    )
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="robot YAML to write, e.g. robots/my_robot.yaml (the "
        "MJCF goes to sim/NAME/ beside a robots/ folder, else to NAME/ beside the YAML)",
    )
    p.add_argument("--name", help="robot name (default: the YAML file's name)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument(
        "--arm",
        action="append",
        default=[],
        metavar="SIDE=J1,J2,...",
        help="the joints of the left or right arm, shoulder first (repeat for both arms)",
    )
    p.add_argument("--head", metavar="J1,J2,...", help="the head's joints, neck first")
    p.add_argument(
        "--hold",
        action="append",
        default=[],
        metavar="J=RAD",
        help="hold joint J at RAD radians (e.g. a knee of a robot that stands bent)",
    )
    p.add_argument(
        "--forward",
        choices=["+x", "-x", "+y", "-y"],
        help="the description's forward axis (default: found from the limbs' names or the feet)",
    )
    p.add_argument(
        "--map",
        type=Path,
        metavar="YAML",
        help="overrides as one file: {arms: {left: [..], right: [..]}, head: [..], hold: {J: RAD}, forward: +y}",
    )
    p.add_argument(
        "--search-path",
        action="append",
        default=[],
        type=Path,
        metavar="DIR",
        help="a folder outside the description's own that it may read (meshes, xacro includes)",
    )
    p.set_defaults(func=cmd_import)  # fmt: skip

    p = sub.add_parser(
        "import-lerobot-calibration",
        help="servo zero offsets, directions and limits from a LeRobot calibration file, into a copy of a robot YAML",
    )
    p.add_argument(
        "calibration", type=Path, help="LeRobot calibration .json (~/.cache/huggingface/lerobot/calibration)"
    )
    p.add_argument("--robot", required=True, help="robot name or YAML path whose servos it calibrates")
    p.add_argument(
        "--out",
        type=Path,
        help="calibrated YAML to write: base: ROBOT and the calibrated values only, so it survives moves "
        "(docs/servos.md; default: NAME_calibrated.yaml beside the robot's)",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.set_defaults(func=cmd_import_lerobot_calibration)


def report_validation(name_or_path: str | Path) -> int:
    """Print every problem (file, key, fix) or one line saying the robot passed; ConfigError when any problem."""
    from robogest.tools.validate import validate

    problems = validate(name_or_path)
    for p in problems:
        print(p)
    if problems:
        raise ConfigError(f"robot {name_or_path}: {len(problems)} problem(s), listed above; fix them, then validate")
    print(f"{name_or_path}: valid (YAML, MuJoCo model, servos, home keyframe, retargeting)")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    return report_validation(args.robot)


def _overrides(args: argparse.Namespace) -> dict:
    """--map, then --arm/--head/--hold/--forward on top of it; one InputError line for a malformed value."""
    from robogest.errors import InputError

    out: dict = {}
    if args.map is not None:
        from robogest.fileio import load_yaml, read_text_capped
        from robogest.robot.config import ImportRecord

        try:
            raw = load_yaml(read_text_capped(args.map, what="--map"))
            if raw is not None and not isinstance(raw, dict):
                raise InputError(
                    f"--map {args.map}: a {type(raw).__name__}, not a mapping; write arms/head/hold/forward as in "
                    "the import: section of an imported robot"
                )
            out = ImportRecord.model_validate({"source": str(args.map), **(raw or {})}).model_dump(exclude={"source"})
        except Exception as e:
            if isinstance(e, InputError):
                raise
            raise InputError(f"--map {args.map}: {' '.join(str(e).split())[:300]}; write arms/head/hold/forward "
                             "as in the import: section of an imported robot") from None  # fmt: skip
        out = {k: v for k, v in out.items() if v}
    for a in args.arm:
        side, _, joints = a.partition("=")
        if side not in ("left", "right") or not joints:
            raise InputError(f"--arm {a}: write --arm left=J1,J2,... or --arm right=J1,J2,...")
        out.setdefault("arms", {})[side] = [j for j in joints.split(",") if j]
    if args.head:
        out["head"] = [j for j in args.head.split(",") if j]
    for h in args.hold:
        joint, _, rad = h.partition("=")
        try:
            out.setdefault("hold", {})[joint] = float(rad)
        except ValueError:
            raise InputError(f"--hold {h}: write --hold JOINT=RADIANS, e.g. --hold left_knee=0.3") from None
    if args.forward:
        out["forward"] = args.forward
    return out


def print_parts(parts: Parts) -> None:
    """The table the user checks: each part, its joints in chain order, and why."""
    from robogest.cli.common import TextTable, print_table

    t = TextTable("body parts found (check them; override with --arm/--head/--hold/--forward)",
                  ["part", "joints (chain order)", "why"])  # fmt: skip
    for part, joints, why in parts.rows:
        t.rows.append([part, ", ".join(joints), why])
    print_table(t)


def cmd_import(args: argparse.Namespace) -> int:
    from robogest.cli.checks import check_outputs
    from robogest.tools.importer import import_description

    check_outputs({"--out": args.out}, {"description": args.description})
    res = import_description(args.description, args.out, name=args.name, overwrite=args.force,
                             overrides=_overrides(args), search_paths=args.search_path)  # fmt: skip
    print(f"wrote {res.yaml_path}, {res.mjcf_path}, {res.scene_path}")
    if res.parts is not None:  # the importer always finds parts; None only from a hand-made result
        print_parts(res.parts)
    print("guessed (edit the YAML and the MJCF, or import again with overrides, to change it):")
    for g in res.guesses:
        print(f"  - {g}")
    return report_validation(res.yaml_path)


def cmd_import_lerobot_calibration(args: argparse.Namespace) -> int:
    from robogest.cli.checks import check_outputs
    from robogest.robot.registry import find_robot
    from robogest.tools.lerobot_calibration import import_lerobot_calibration

    robot = find_robot(args.robot)
    check_outputs({"--out": args.out}, {"CALIBRATION": args.calibration, "--robot": robot.path})
    res = import_lerobot_calibration(args.calibration, robot, args.out, overwrite=args.force)
    print(f"wrote {res.path} (the original is unchanged)")
    for c in res.changes:
        print(f"  - {c}")
    return report_validation(res.path)
