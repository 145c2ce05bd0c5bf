"""Read a LeRobot calibration file into a robot YAML's servo zero offsets, directions and joint limits.

LeRobot (``lerobot-calibrate``) stores one JSON per arm, under ``~/.cache/huggingface/lerobot/calibration/``::

    {"shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1470, "range_min": 758, "range_max": 3292}, ...}

It writes ``homing_offset`` into each servo (Feetech: reported position = actual - offset), so that the pose the user
held while calibrating reads half a turn, and records the range of motion in those offset-corrected ticks. LeRobot's
joint angle in degrees is then ``(ticks - mid) * 360 / (resolution - 1)`` with ``mid`` the middle of the recorded
range; ``drive_mode`` 1 marks a motor whose sign LeRobot flips.

robogest reads the same offset-corrected ticks from the servo (the homing offset stays in the servo and is not
applied again), so for a robot whose joint zero and signs are LeRobot's (the shipped ``so101_sts3215``):

- ``zero_offset_rad = (mid - centre_tick) * 2 pi / ticks_per_rev`` (joint zero = LeRobot's zero, the range middle);
- ``direction = -1`` where ``drive_mode`` is 1, else ``+1``;
- joint limits = the recorded range, ``direction * (range - mid) * 2 pi / ticks_per_rev / gear_ratio``, intersected
  with the YAML's limits (a calibration never widens a limit beyond the model's).

Motors are matched to the robot's joints by name, and each must have its joint's servo id: a calibration of another
robot (or of a LeRobot type with the other servo family, told by the folder it lies in) is refused, not matched.

The copy names the robot it calibrates (``base: so101_sts3215``, :mod:`robogest.robot.inherit`) and holds only the
calibrated values, so moving it or reinstalling robogest keeps it working (a copied ``model:`` path did not).

robogest uses the model's ticks per revolution (4096 for an STS3215), LeRobot ``resolution - 1`` (4095): 0.02 %.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robogest.errors import ConfigError, InputError
from robogest.fileio import load_yaml, read_text_capped
from robogest.robot.config import LIMIT_MARGIN_RAD, RobotConfig
from robogest.robot.yaml_edit import write_robot_yaml

_FIELDS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")


@dataclass(frozen=True)
class MotorCalibration:
    """One motor of a LeRobot calibration file (ticks of the servo, after its homing offset)."""

    id: int
    drive_mode: int
    homing_offset: int
    range_min: int
    range_max: int


#: Largest calibration file read, bytes (one is about 1 kB per motor).
MAX_CALIBRATION_BYTES = 1024**2

#: The servo family of each LeRobot robot or teleoperator type, as its calibration folder is named
#: (``calibration/robots/so101_follower/``): a calibration under one of these folders is for that family only.
LEROBOT_FAMILIES = {
    "so100": "feetech", "so101": "feetech", "bi_so100": "feetech", "lekiwi": "feetech", "hope_jr": "feetech",
    "homunculus": "feetech", "koch": "dynamixel", "widowx": "dynamixel", "viperx": "dynamixel",
}  # fmt: skip


def family_of(path: str | Path) -> tuple[str, str] | None:
    """``(servo family, folder)`` from the LeRobot type folder ``path`` lies in (``so101_follower``: feetech);
    None when that folder names no known type."""
    folder = Path(path).parent.name
    for kind, family in LEROBOT_FAMILIES.items():
        if folder == kind or folder.startswith(f"{kind}_"):
            return family, folder
    return None


def read_calibration(path: str | Path) -> dict[str, MotorCalibration]:
    """Motor name -> calibration; InputError naming the file and motor for anything that is not LeRobot's format."""
    path = Path(path)
    text = read_text_capped(path, MAX_CALIBRATION_BYTES, "calibration")
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not JSON ({e.msg} at line {e.lineno}); pass a LeRobot calibration .json") from None
    except RecursionError:
        raise InputError(f"{path}: JSON nested too deeply to be a LeRobot calibration file") from None
    except ValueError as e:  # an integer of over 4300 digits
        raise InputError(f"{path}: not a LeRobot calibration file ({e})") from None
    if not isinstance(raw, dict) or not raw:
        raise InputError(f"{path}: expected {{motor name: {{{', '.join(_FIELDS)}}}}} as LeRobot writes it")
    out = {}
    for motor, entry in raw.items():
        missing = [f for f in _FIELDS if not isinstance(entry, dict) or f not in entry]
        if missing:
            raise InputError(f"{path}: motor {motor!r} lacks {missing}; is this a LeRobot calibration file?")
        bad = [f for f in _FIELDS if not isinstance(entry[f], int) or isinstance(entry[f], bool)]
        if bad:
            raise InputError(f"{path}: motor {motor!r}: {bad} must be integers (ticks)")
        cal = MotorCalibration(**{f: entry[f] for f in _FIELDS})
        if not 0 <= cal.range_min < cal.range_max:
            raise InputError(
                f"{path}: motor {motor!r}: range_min {cal.range_min} must be >= 0 and below range_max "
                f"{cal.range_max}; recalibrate the motor"
            )
        if cal.drive_mode not in (0, 1):
            raise InputError(f"{path}: motor {motor!r}: drive_mode {cal.drive_mode} is not 0 or 1")
        out[str(motor)] = cal
    return out


def _check_matches(calib: dict[str, MotorCalibration], calib_path: str | Path, robot: RobotConfig) -> None:
    """Refuse a calibration of another robot: motors not named after this robot's joints, ids other than its
    servos', or a LeRobot folder of the other servo family. (Matched by id, an SO-101's calibration gave six of a
    Dynamixel humanoid's joints its zero offsets, and the copy was "valid".)"""
    assert robot.bus is not None  # checked by the caller
    hint = family_of(calib_path)
    if hint is not None and hint[0] != robot.bus.family:
        raise InputError(
            f"{calib_path}: a calibration of a {hint[1]} ({hint[0]} servos), not of {robot.name} "
            f"({robot.bus.family} servos); pass this robot's calibration; nothing written"
        )
    strangers = [m for m in calib if m not in robot.bus.servos]
    if strangers:
        raise InputError(
            f"{calib_path}: motors {strangers} are not joints of {robot.name} (its joints: "
            f"{', '.join(robot.joint_names)}); a calibration of another robot? Motors are matched to joints by "
            "name; nothing written"
        )
    moved = [f"{m} (id {c.id}; {robot.name}: id {robot.bus.servos[m].id})" for m, c in calib.items()
             if c.id != robot.bus.servos[m].id]  # fmt: skip
    if moved:
        raise InputError(
            f"{calib_path}: motors {', '.join(moved)} have other servo ids than the robot file gives them; a "
            "calibration of another arm? Fix the ids in the robot file's bus.servos, or recalibrate; nothing written"
        )


def _overlay(robot: RobotConfig, out: Path) -> tuple[str, dict[str, Any]]:
    """``(base name, what the copy holds beside it)``. The copy names its base robot (``base:``) instead of copying
    it: ``robot`` itself, or, when ``robot`` has a base, that base with ``robot``'s own changes kept. The name must
    find that same file from ``out``'s folder (:func:`robogest.robot.registry.find_base`)."""
    from robogest.robot.registry import find_base

    assert robot.path is not None
    base_path: Path | None
    if robot.base is None:
        base, base_path, overlay = robot.path.stem, robot.path, {}
    else:
        base, base_path = robot.base, robot.base_path
        raw = load_yaml(read_text_capped(robot.path, what="robot file"))
        if not isinstance(raw, dict):  # it loaded as a robot a moment ago: only a file changed meanwhile
            raise InputError(f"{robot.path}: no longer a YAML mapping of robot keys; load it again")
        overlay = {k: v for k, v in raw.items() if k not in ("name", "base", "description")}
        if "model" in overlay:  # relative to the robot's folder, not necessarily the copy's
            overlay["model"] = str(robot.model_path)
    found = find_base(base, out.resolve())
    if found is None or base_path is None or found.resolve() != base_path.resolve():
        raise InputError(
            f"--out {out}: the copy names its base robot {base!r} ({base_path}), but from {out.parent} that name "
            f"finds {found or 'no robot'}; write the copy beside {base_path}, or put its folder on $ROBOGEST_ROBOTS;"
            " nothing written"
        )
    return base, overlay


def _joint_entry(overlay: dict[str, Any], name: str) -> dict[str, Any]:
    """The copy's entry for joint ``name`` (added when missing)."""
    joints = overlay.setdefault("joints", [])
    entry = next((j for j in joints if j.get("name") == name), None)
    if entry is None:
        entry = {"name": name}
        joints.append(entry)
    return entry


@dataclass
class CalibrationImport:
    """The YAML written and one line per change (what the calibration set, what it narrowed)."""

    path: Path
    changes: list[str]


def import_lerobot_calibration(
    calib_path: str | Path, robot: RobotConfig, out: str | Path | None = None, overwrite: bool = False
) -> CalibrationImport:
    """Write a robot YAML with the servo mapping and limits from a LeRobot calibration file, over ``robot``.

    The copy goes to ``out`` (default ``NAME_calibrated.yaml`` beside the original) and is named after its file;
    it holds ``base: NAME`` (``robot``, found by name when loaded) and only the calibrated values; the original is
    never written.
    """
    from robogest.backends import get_backend_factory

    calib = read_calibration(calib_path)
    src = robot.path
    if src is None or robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section; a calibration maps servos, add bus: first")
    _check_matches(calib, calib_path, robot)
    out = Path(out) if out is not None else src.with_name(f"{src.stem}_calibrated.yaml")
    if out.resolve() == src.resolve():
        raise InputError(f"--out {out} is the robot's own YAML; write the calibrated copy elsewhere")
    if out.exists() and not overwrite:
        raise InputError(f"{out} exists; choose another --out or pass --force to overwrite it")
    base, overlay = _overlay(robot, out)
    lookup = getattr(get_backend_factory(robot.bus.family), "lookup_model", None)
    changes: list[str] = []
    for j in robot.joints:
        servo = robot.bus.servos[j.name]
        if j.name not in calib:
            changes.append(f"{j.name}: not in the calibration file; kept")
            continue
        motor, c = j.name, calib[j.name]
        model = lookup(servo.model, robot.bus.protocol) if lookup else None
        tpr, centre = (model.ticks_per_rev, model.centre_tick) if model else (4096, 2048)
        if c.range_max > (model.max_tick if model else 4095):
            raise InputError(
                f"{calib_path}: motor {motor!r}: range_max {c.range_max} is past the {servo.model}'s "
                f"last tick {model.max_tick if model else 4095}"
            )
        mid = 0.5 * (c.range_min + c.range_max)
        rad = 2 * math.pi / tpr
        direction = -1 if c.drive_mode else 1
        zero = (mid - centre) * rad
        ends = sorted(direction * (t - mid) * rad / servo.gear_ratio for t in (c.range_min, c.range_max))
        lower, upper = max(ends[0], j.lower_rad), min(ends[1], j.upper_rad)
        if not lower + LIMIT_MARGIN_RAD <= j.rest_rad <= upper - LIMIT_MARGIN_RAD:
            raise ConfigError(
                f"{calib_path}: motor {motor!r}: the calibrated range [{ends[0]:.3f}, {ends[1]:.3f}] rad leaves no "
                f"room around joint {j.name!r}'s rest pose {j.rest_rad} rad; recalibrate with the arm in"
                " LeRobot's middle pose, or move rest_rad (and the MJCF home key)"
            )
        servos = overlay.setdefault("bus", {}).setdefault("servos", {})
        servos.setdefault(j.name, {}).update(zero_offset_rad=round(zero, 6), direction=direction)
        _joint_entry(overlay, j.name).update(lower_rad=round(lower, 6), upper_rad=round(upper, 6))
        narrowed = [
            f"{w} {old:+.3f} -> {new:+.3f}"
            for w, old, new in (("lower", j.lower_rad, lower), ("upper", j.upper_rad, upper))
            if abs(new - old) > 1e-9
        ]
        changes.append(
            f"{j.name}: motor {motor!r}, range middle tick {mid:g}: zero_offset_rad {zero:+.4f}, direction "
            f"{direction:+d}" + (f"; limits narrowed to the recorded range: {', '.join(narrowed)}" if narrowed else "")
        )
    described = re.sub(r" \(calibrated from [^()]*\)$", "", robot.description)  # a recalibration says it once
    described = f"{described} (calibrated from {Path(calib_path).name})".strip()
    doc = {"name": out.stem, "base": base, "description": described,
           **{k: v for k, v in overlay.items() if k not in ("joints", "bus")}}  # fmt: skip
    doc.update({k: overlay[k] for k in ("joints", "bus") if k in overlay})
    out.parent.mkdir(parents=True, exist_ok=True)
    header = (
        f"# {out.stem}: robot {base} with the servo zero offsets, directions and limits of the LeRobot calibration\n"
        f"# {Path(calib_path).name} (robogest robots import-lerobot-calibration). base: names that robot, found by\n"
        f"# name when this file is loaded; every key not here is {base}'s (docs/servos.md).\n"
    )
    try:  # only a copy that loads replaces anything
        write_robot_yaml(out, doc, header)
    except ConfigError as e:
        raise ConfigError(f"{calib_path}: the calibrated copy would not load: {e}") from None
    return CalibrationImport(out, changes)
