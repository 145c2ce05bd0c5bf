"""The robot YAML an import writes (held joints, the retargeting proposal, the import record, a bus proposal), and
the staging folder that makes an import all-or-nothing: everything is written beside the destination first and
moved into place at the end, so a failed import (an error, Ctrl-C, a full disk) leaves nothing behind."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from robogest.errors import InputError
from robogest.fileio import atomic_path, write_error

#: Joint limits the YAML proposes, relative to the description's: 65 % of its velocity, a gentle acceleration.
VELOCITY_SHARE = 0.65
ACCELERATION_RAD_S2 = 15.0


@dataclass
class YamlParts:
    """Everything the YAML says, in joint order."""

    name: str
    source: str
    model: str
    joints: list[str]
    ranges: dict[str, tuple[float, float]]
    velocity: dict[str, float]
    rest: dict[str, float]
    held: dict[str, str]
    vectors: list[tuple[str, str, str, str, float]]
    record: dict
    servo_models: dict[str, str]
    guesses: list[str] = field(default_factory=list)
    flip: bool = False


def _flow(d: dict) -> str:
    return yaml.safe_dump(d, default_flow_style=True, sort_keys=False, width=10_000).strip()


def yaml_text(p: YamlParts) -> str:
    rows = []
    for jn in p.joints:
        lo, hi = p.ranges[jn]
        row = {"name": jn, "lower_rad": float(f"{lo:.10g}"), "upper_rad": float(f"{hi:.10g}"),
               "max_velocity_rad_s": round(VELOCITY_SHARE * p.velocity[jn], 2),
               "max_acceleration_rad_s2": ACCELERATION_RAD_S2, "rest_rad": float(f"{p.rest[jn]:.6g}")}  # fmt: skip
        if jn in p.held:
            row["held"] = True
        rows.append(f"  - {_flow(row)}" + (f"  # {p.held[jn]}" if jn in p.held else ""))
    vecs = [f"  - {_flow({'human': [h0, h1], 'robot': [s0, s1], **({'weight': w} if w != 1 else {})})}"
            for h0, h1, s0, s1, w in p.vectors]  # fmt: skip
    notes = "\n".join(f"#   - {g}" for g in p.guesses)
    frame = "retarget_frame_rpy_rad: [3.141592653589793, 0.0, 0.0]\n" if p.flip else ""
    record = yaml.safe_dump({"import": p.record}, sort_keys=False, width=110).strip()
    return f"""# {p.name}: imported from {p.source} by `robogest robots import`. Check it with
# `robogest robots validate {p.name}` after every edit; import again (same --out, --force) to redo it with
# the overrides recorded under `import:` below.
#
# Guessed (the MJCF's home keyframe must equal rest_rad):
{notes}
# Velocity limits: {VELOCITY_SHARE:.0%} of the description's; accelerations {ACCELERATION_RAD_S2:g} rad/s^2.
# Held joints (held: true) stay at rest_rad: legs, feet, fingers, eyes, jaw, and the waist unless mapped.
name: {p.name}
description: imported from {p.source}
model: {p.model}
joints:
{chr(10).join(rows)}
{frame}retarget:
{chr(10).join(vecs)}
{record}
{bus_proposal(p.joints, p.servo_models)}"""


def bus_proposal(joints: list[str], models: dict[str, str]) -> str:
    """A commented ``bus:`` section: the servo models the description names (its most common one where a joint
    names none), else a template; ids in chain order. Commented: check ids, offsets and directions first."""
    found = Counter(models.values())
    if found:
        family, common = found.most_common(1)[0][0].split(":")
        names = ", ".join(sorted({v.split(":")[1] for v in models.values()}))
        head = (f"# Servos named in the description ({names}): a proposal; check each id, zero_offset_rad and "
                "direction with `robogest servo scan`, then uncomment")  # fmt: skip
    else:
        family, common = "feetech", "STS3215"
        head = "# To drive real servos, add a bus section (ids, models, offsets; see the shipped robots), e.g.:"
    proto = "2.0" if family == "dynamixel" else "0"
    lines = [head, "# bus:", f"#   family: {family}", f"#   protocol: {proto}", "#   servos:"]
    for i, jn in enumerate(joints):
        model = models.get(jn, f"{family}:{common}").split(":")[1]
        lines.append(f"#     {jn}: {{id: {i + 1}, model: {model}}}")
    return "\n".join(lines) + "\n"


class Staging:
    """Build an import in a hidden folder beside ``model_dir``, then move it and the YAML into place together;
    on any failure (including a full disk or Ctrl-C) remove the staging folder and every folder it created, and
    leave what was there before."""

    def __init__(self, model_dir: Path, yaml_path: Path):
        self.model_dir, self.yaml_path = model_dir, yaml_path
        self.created: list[Path] = []
        for folder in (model_dir.parent, yaml_path.parent):
            missing = []
            while not folder.exists():
                missing.append(folder)
                folder = folder.parent
            for f in reversed(missing):
                try:
                    f.mkdir()
                except OSError as e:
                    self.abort()
                    raise write_error(f, e) from None
                self.created.append(f)
        try:
            self.dir = Path(tempfile.mkdtemp(prefix=f".{model_dir.name}.import-", dir=model_dir.parent))
        except OSError as e:
            self.abort()
            raise write_error(model_dir, e) from None

    def abort(self) -> None:
        if hasattr(self, "dir"):
            shutil.rmtree(self.dir, ignore_errors=True)
        for f in reversed(self.created):
            with contextlib.suppress(OSError):
                f.rmdir()

    def publish(self, yaml_text: str) -> None:
        """The model folder replaces ``model_dir`` (an old one, written by an import, is kept until the YAML is
        written), then the YAML is written atomically."""
        old = None
        try:
            if self.model_dir.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{self.model_dir.name}.old-", dir=self.model_dir.parent))
                os.replace(self.model_dir, old / "m")
            os.replace(self.dir, self.model_dir)
            try:
                with atomic_path(self.yaml_path) as tmp:
                    tmp.write_text(yaml_text)
            except BaseException:
                shutil.rmtree(self.model_dir, ignore_errors=True)
                if old is not None:
                    os.replace(old / "m", self.model_dir)
                raise
        except OSError as e:
            raise write_error(self.model_dir, e) from None
        finally:
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)


def check_replaceable(model_dir: Path, yaml_path: Path, name: str, overwrite: bool) -> None:
    """Outputs that exist need --force, and a model folder is only ever replaced if an import wrote it."""
    for p in (yaml_path, model_dir):
        if p.exists() and not overwrite:
            raise InputError(f"{p} exists; choose another --out or pass --force to overwrite it")
    if model_dir.exists() and not (model_dir / f"{name}.xml").is_file():
        raise InputError(f"{model_dir} exists and holds no {name}.xml from an import; robogest will not replace a "
                         "folder it did not write: move it or choose another --out")  # fmt: skip
