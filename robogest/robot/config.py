"""Robot definitions: ``robots/<name>.yaml`` validated into :class:`RobotConfig`.

Robots are data. Every field a stage needs is here, validated once at the boundary so that a typo in a
YAML file produces one message naming the file, the key and the fix, never a traceback deep inside IK.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import UnionType
from typing import Literal, Union, get_args, get_origin

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from robogest.errors import ConfigError, InputError
from robogest.fileio import load_yaml, read_text_capped

#: Human joints (canonical skeleton names) a retargeting vector may start or end at.
HUMAN_POINTS = (
    "pelvis", "spine", "spine1", "spine2", "neck", "head", "nose",
    "l_collar", "l_shoulder", "l_elbow", "l_wrist", "l_hand",
    "r_collar", "r_shoulder", "r_elbow", "r_wrist", "r_hand",
)  # fmt: skip

#: The band every safety stage keeps inside a joint's hard limits (batch tracker, streaming planner, the control
#: loop's online limiter), and the room a rest pose needs from them: the one margin, radians.
LIMIT_MARGIN_RAD = 0.02
#: Default jerk limit rule: the acceleration limit is reached from zero in this many seconds.
JERK_RISE_S = 0.05
#: Limits a servo joint can plausibly have (the fastest hobby servos turn at about 10 rad/s). Outside them a value
#: is a unit mistake, and the safety layer's time bounds, sized from the limits, would be absurd (1e-6 rad/s²
#: asked for more memory than the machine has; 1e308 rad/s overflowed).
PLAUSIBLE_VELOCITY_RAD_S = (0.01, 100.0)
PLAUSIBLE_ACCELERATION_RAD_S2 = (0.05, 1e4)
PLAUSIBLE_JERK_RAD_S3 = (0.5, 1e7)
#: Gearing between servo and joint a robot can plausibly have: beyond it a value is a typo (``gear_ratio: 1.0e-300``
#: passed validation and the joint never moved: every goal rounded to the servo's zero tick).
PLAUSIBLE_GEAR_RATIO = (0.01, 100.0)
#: A servo's zero offset is an angle of the servo shaft: within one turn either way.
MAX_ZERO_OFFSET_RAD = 2 * math.pi
#: Serial baud rates the supported adapters can run (the CLI's ``--baud`` takes the same).
PLAUSIBLE_BAUD = (300, 20_000_000)


def _scalar_types(annotation: object) -> set[type]:
    """The scalar types a field's annotation accepts (those of a ``Literal``'s values; through unions)."""
    origin, args = get_origin(annotation), get_args(annotation)
    if origin is Literal:
        return {type(a) for a in args}
    if origin in (Union, UnionType):
        return set().union(*(_scalar_types(a) for a in args))
    return {annotation} if isinstance(annotation, type) else set()


def _mistyped(annotation: object, v: object) -> object | None:
    """The value in ``v`` (or, for a tuple/list field, in its items) that lax pydantic would coerce into a
    number although it is written as a boolean or as text: ``true`` reads as 1 (``direction: true`` would
    silently mean "not reversed"), ``"3.0"`` as 3.0. None when there is none."""
    origin, args = get_origin(annotation), get_args(annotation)
    if origin in (tuple, list) and isinstance(v, (list, tuple)):
        items = [a for a in args if a is not Ellipsis]
        for k, item in enumerate(v):
            bad = _mistyped(items[min(k, len(items) - 1)], item) if items else None
            if bad is not None:
                return bad
        return None
    types = _scalar_types(annotation)
    numeric = bool(types & {int, float})
    if isinstance(v, bool) and numeric and bool not in types:
        return v
    if isinstance(v, str) and numeric and str not in types:
        return v
    return None


class _Strict(BaseModel):
    # allow_inf_nan=False: every number in a robot file (limits, rest, speeds, offsets, gear ratios, retarget
    # weights, frame angles) must be finite; NaN or .inf is refused naming the key.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_numbers(cls, v: object, info: ValidationInfo) -> object:
        # Lax pydantic reads `true` as 1.0 and "3.0" as 3.0: a quoted or boolean number is a mistake, not a number.
        assert info.field_name is not None  # a field validator ("*") always runs for a field
        bad = _mistyped(cls.model_fields[info.field_name].annotation, v)
        if bad is None:
            return v
        if isinstance(bad, str) and _is_float_text(bad):  # YAML 1.1 reads 1e-6 (no dot) as text
            raise ValueError(f"{bad!r} is read as text, not a number; write it with a decimal point (e.g. 1.0e-6)")
        raise ValueError(f"{bad!r} is not a number; write the value unquoted (e.g. 3.0)")


def _is_float_text(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return "e" in text.lower() and text.strip() == text


class JointConfig(_Strict):
    """One actuated joint; angles in radians at the joint (after any gearing)."""

    name: str
    lower_rad: float
    upper_rad: float
    max_velocity_rad_s: float = Field(gt=0)
    max_acceleration_rad_s2: float = Field(gt=0)
    rest_rad: float = 0.0
    #: Jerk limit, rad/s³; default ``max_acceleration_rad_s2 / JERK_RISE_S`` (see :attr:`jerk_rad_s3`).
    max_jerk_rad_s3: float | None = Field(default=None, gt=0)
    #: A joint that does not gesture (a humanoid's legs, feet, fingers): held at ``rest_rad``. Retargeting, the
    #: generator, idle motion and the safety stages never move it, and servos are only ever commanded to that angle.
    held: bool = False

    @property
    def jerk_rad_s3(self) -> float:
        """The jerk limit in force: the YAML's, or by default the acceleration limit reached from zero in
        :data:`JERK_RISE_S` (50 ms, 2.5 ticks at 50 Hz): no step in acceleration reaches the servos, and a stop
        from full speed takes only about 50 ms longer than without a jerk limit."""
        if self.max_jerk_rad_s3 is not None:
            return self.max_jerk_rad_s3
        return self.max_acceleration_rad_s2 / JERK_RISE_S

    @model_validator(mode="after")
    def _check(self) -> JointConfig:
        for key, (lo, hi), unit in (
            ("max_velocity_rad_s", PLAUSIBLE_VELOCITY_RAD_S, "rad/s"),
            ("max_acceleration_rad_s2", PLAUSIBLE_ACCELERATION_RAD_S2, "rad/s²"),
            ("max_jerk_rad_s3", PLAUSIBLE_JERK_RAD_S3, "rad/s³"),
        ):
            v = getattr(self, key)
            if v is not None and not lo <= v <= hi:
                raise ValueError(
                    f"{key} = {v:g} {unit} is outside [{lo:g}, {hi:g}], what a servo joint can have; check the units"
                )
        if not self.lower_rad < self.upper_rad:
            raise ValueError(f"lower_rad ({self.lower_rad}) must be below upper_rad ({self.upper_rad})")
        if not self.lower_rad <= self.rest_rad <= self.upper_rad:
            raise ValueError(f"rest_rad ({self.rest_rad}) must lie within [lower_rad, upper_rad]")
        return self


class RetargetVector(_Strict):
    """Match the direction of a human bone (``human: [from, to]``) to a robot link (``robot: [site, site]``)."""

    human: tuple[str, str]
    robot: tuple[str, str]
    weight: float = Field(default=1.0, gt=0)

    @model_validator(mode="after")
    def _check(self) -> RetargetVector:
        for p in self.human:
            if p not in HUMAN_POINTS:
                raise ValueError(f"human point {p!r} is not a canonical joint; use one of {', '.join(HUMAN_POINTS)}")
        return self


class ServoConfig(_Strict):
    """Hardware mapping of one joint: ``q_servo = direction * q_joint * gear_ratio + zero_offset_rad``."""

    id: int = Field(ge=0, le=252)
    model: str
    zero_offset_rad: float = 0.0
    direction: Literal[1, -1] = 1
    gear_ratio: float = Field(default=1.0, gt=0)

    @model_validator(mode="after")
    def _check(self) -> ServoConfig:
        lo, hi = PLAUSIBLE_GEAR_RATIO
        if not lo <= self.gear_ratio <= hi:
            raise ValueError(
                f"gear_ratio = {self.gear_ratio:g} is outside [{lo:g}, {hi:g}], what a servo's gearing can be; "
                "write servo turns per joint turn (1.0 for a direct drive)"
            )
        if not abs(self.zero_offset_rad) <= MAX_ZERO_OFFSET_RAD:
            raise ValueError(
                f"zero_offset_rad = {self.zero_offset_rad:g} is more than one turn ({MAX_ZERO_OFFSET_RAD:.4f} rad) "
                "either way; check the units are radians"
            )
        return self


class BusConfig(_Strict):
    """Optional hardware section: servo family, protocol and per-joint servos."""

    family: Literal["dynamixel", "feetech"]
    protocol: float = 2.0
    baudrate: int = Field(default=1_000_000, ge=PLAUSIBLE_BAUD[0], le=PLAUSIBLE_BAUD[1])
    port: str | None = None
    servos: dict[str, ServoConfig]

    @model_validator(mode="after")
    def _check(self) -> BusConfig:
        allowed = {"dynamixel": (1.0, 2.0), "feetech": (0.0, 1.0)}[self.family]
        if self.protocol not in allowed:
            raise ValueError(
                f"protocol {self.protocol} is not valid for {self.family}; use one of {allowed}"
                " (feetech: 0 = STS/SMS little-endian, 1 = SCS big-endian)"
            )
        ids = [s.id for s in self.servos.values()]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"servo ids {dup} are used by more than one joint; give each servo its own id")
        return self


class ImportRecord(_Strict):
    """How ``robogest robots import`` read the robot, kept so that importing again keeps the user's overrides.
    Only the importer reads it."""

    source: str
    arms: dict[Literal["left", "right"], list[str]] = Field(default_factory=dict)
    head: list[str] = Field(default_factory=list)
    hold: dict[str, float] = Field(default_factory=dict)
    forward: Literal["+x", "-x", "+y", "-y"] | None = None


class RobotConfig(_Strict):
    """A whole robot. ``model`` is the MJCF path, relative to the YAML file (absolute when it came from a base)."""

    name: str
    #: ``base: NAME``: the file holds only what differs from robot NAME (:mod:`robogest.robot.inherit`).
    base: str | None = None
    description: str = ""
    model: str
    joints: list[JointConfig] = Field(min_length=1)
    retarget: list[RetargetVector] = Field(min_length=1)
    #: Fixed rotation (roll, pitch, yaw about the robot's x, y, z) applied to human directions before
    #: matching, for robots whose natural workspace differs from a person's (a desk arm reaching up where
    #: a person's arm hangs down). Zero for humanoids.
    retarget_frame_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bus: BusConfig | None = None
    #: Written by ``robogest robots import`` (YAML key ``import``): the description and the overrides it used.
    import_record: ImportRecord | None = Field(default=None, validation_alias="import", serialization_alias="import")
    path: Path | None = Field(default=None, exclude=True)
    #: The YAML of ``base`` as found when this file was loaded.
    base_path: Path | None = Field(default=None, exclude=True)

    @model_validator(mode="after")
    def _check(self) -> RobotConfig:
        names = [j.name for j in self.joints]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"joints {dup} appear more than once")
        if self.bus is not None:
            missing = [n for n in names if n not in self.bus.servos]
            extra = [n for n in self.bus.servos if n not in names]
            if missing and extra:  # most often one name mistyped in joints or in bus.servos
                raise ValueError(
                    f"bus.servos has no entry for joints {missing} but names {extra}, which are not joints: a typo in"
                    " one of the two? `robogest robots validate` checks both against the MuJoCo model"
                )
            if missing:
                raise ValueError(f"bus.servos has no entry for joints {missing}; add one per joint")
            if extra:
                raise ValueError(f"bus.servos names {extra}, which are not joints of this robot")
        return self

    # --- arrays in joint order, for the vectorised stages -------------------------------------
    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def q_min_rad(self) -> np.ndarray:
        """``(J,)`` lower limits, radians."""
        return np.array([j.lower_rad for j in self.joints])

    @property
    def q_max_rad(self) -> np.ndarray:
        return np.array([j.upper_rad for j in self.joints])

    @property
    def v_max_rad_s(self) -> np.ndarray:
        return np.array([j.max_velocity_rad_s for j in self.joints])

    @property
    def a_max_rad_s2(self) -> np.ndarray:
        return np.array([j.max_acceleration_rad_s2 for j in self.joints])

    @property
    def j_max_rad_s3(self) -> np.ndarray:
        """``(J,)`` jerk limits, rad/s³: YAML ``max_jerk_rad_s3`` or the default (:attr:`JointConfig.jerk_rad_s3`)."""
        return np.array([j.jerk_rad_s3 for j in self.joints])

    @property
    def rest_q_rad(self) -> np.ndarray:
        return np.array([j.rest_rad for j in self.joints])

    @property
    def held_mask(self) -> np.ndarray:
        """``(J,)`` bool: joints held at their rest angle (:attr:`JointConfig.held`)."""
        return np.array([j.held for j in self.joints], dtype=bool)

    @property
    def model_path(self) -> Path:
        base = self.path.parent if self.path is not None else Path.cwd()
        return (base / self.model).resolve()


def _format_loc(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(top level)"


def load_robot_config(path: str | Path) -> RobotConfig:
    """Read and validate one robot YAML; every problem becomes a :class:`ConfigError` naming file and key.

    A file with ``base: NAME`` is merged onto robot NAME first (:mod:`robogest.robot.inherit`)."""
    return _load(Path(path), ())


def _load(path: Path, chain: tuple[Path, ...]) -> RobotConfig:
    """:func:`load_robot_config`; ``chain``: the files whose bases led here (to refuse a loop)."""
    try:
        raw = load_yaml(read_text_capped(path, what="robot file"))
    except InputError as e:  # missing, not a regular file, too large, not UTF-8: a bad robot file (exit 3)
        raise ConfigError(str(e)) from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {' '.join(str(e).split())}") from None
    except RecursionError:
        raise ConfigError(f"{path}: YAML nested too deeply to be a robot file") from None
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a mapping with keys name, model, joints, retarget")
    base_path, merged = None, ""
    if raw.get("base") is not None:
        from robogest.robot.inherit import resolve_base

        raw, base_path = resolve_base(raw, path, chain, _load)
        merged = f" (merged onto base {raw['base']}, {base_path})"
    try:
        cfg = RobotConfig.model_validate({**raw, "path": path, "base_path": base_path})
    except ValidationError as e:
        problems = []
        for err in e.errors():
            msg = err["msg"].removeprefix("Value error, ")
            if err["type"] == "finite_number":
                msg = f"{err['input']!r} is not a finite number; write a real value (NaN and .inf are not allowed)"
            problems.append(f"key {_format_loc(err['loc'])}: {msg}")
        # One line (the CLI prints every error as one line), every problem in it.
        raise ConfigError(f"{path}: invalid robot definition: " + "; ".join(problems) + merged) from None
    if not cfg.model_path.is_file():
        raise ConfigError(
            f"{path}: key model: MuJoCo file {cfg.model_path} does not exist; fix the path (relative to the YAML)"
        )
    for j in cfg.joints:
        if j.upper_rad - j.lower_rad > 2 * math.pi + 1e-9:
            raise ConfigError(f"{path}: joint {j.name!r}: range wider than one turn; check the units are radians")
    return cfg
