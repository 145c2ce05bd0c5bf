"""The default generator's gesture repertoire, as data: YAML files of units authored as key poses.

Each unit is a *prep* pose (where the stroke starts) and a *stroke* pose (where it ends), both as angle
offsets from :data:`poses.READY` at full amplitude (angle names: :data:`poses.DOF_NAMES`, or
``both_<arm angle>``); the generator scales them by the beat's prominence and times the stroke so its
speed peak lands on an acoustic beat. Beat units are picked by a statistical interpreter (Rhythmic
Gesticulator §7.4.6); semantic units by their trigger words, by priority within a sentence.

Files are read from ``$ROBOGEST_GESTURES`` (os.pathsep-separated folders) and then the built-in
``gestures/`` folder beside this module; a unit in an earlier folder replaces a built-in one of the same
name, so a user adds or changes a gesture with a file and no code. Every mistake is reported with the file
and the key, e.g. ``my.yaml: key units.wave.stroke.r_elbw: unknown pose angle ...``.

File format::

    units:
      wave_hello:                 # unit name
        channel: arms             # arms (default) or head
        hand: right               # right | left | both | none
        size: medium              # small | medium | large
        kind: semantic            # beat (picked on ordinary beats) or semantic (picked by triggers/tags)
        priority: 3               # semantic: higher wins within a sentence
        frequency: 0.05           # beat: target share among beat units
        triggers: [hello, hi]     # words or word pairs ("over there"); "?" = the last word of a question
        prep: {r_elbow: 0.3}      # radians, offsets from READY
        stroke: {r_elbow: -0.2, r_abd: 0.4}
        stroke_s: 0.22            # stroke duration, s (its speed peak is on the beat)
        hold_s: 0.15              # post-stroke hold, s
        shake_hz: 0               # head units: > 0 makes a yaw oscillation
        meaning: the right hand waves hello    # used by the optional sentence-embedding choice
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml

from robogest.errors import ConfigError, InputError
from robogest.fileio import load_yaml, read_text_capped
from robogest.generators.poses import DOF_NAMES, pose

#: Built-in units.
BUILTIN_DIR = Path(__file__).resolve().parent / "gestures"
#: Relative amplitude of each size: prominent beats prefer large units.
SIZE_LEVEL = {"small": 0.3, "medium": 0.6, "large": 1.0}
_KEYS = {
    "channel", "hand", "size", "kind", "priority", "frequency", "triggers", "prep", "stroke", "stroke_s", "hold_s",
    "shake_hz", "meaning",
}  # fmt: skip


@dataclass(frozen=True)
class GestureUnit:
    """One lexeme.

    Attributes
    ----------
    name : str
    prep : ndarray [shape=(D,)], radians
        Offset from READY at the start of the stroke (full amplitude).
    stroke : ndarray [shape=(D,)], radians
        Offset from READY at the end of the stroke.
    stroke_s : float
        Stroke duration, seconds; the speed peak is at its middle, on the beat.
    hold_s : float
        Post-stroke hold before the next movement may start, seconds.
    channel : str
        ``"arms"`` (arms + spine lean) or ``"head"`` (head only, overlays the arms).
    shake_hz : float
        Head units only: > 0 makes a yaw oscillation instead of a single key pose.
    hand, size, kind : str
        ``right|left|both|none``, ``small|medium|large``, ``beat|semantic``.
    priority : int
        Semantic units: higher wins within a sentence.
    frequency : float
        Beat units: target share among the beat units the interpreter picks.
    triggers : tuple of str
        Lower-case words or two-word phrases; ``"?"`` marks the last word of a question.
    meaning : str
        A short description (for people, and for sentence-embedding choice).
    source : str
        The file the unit came from.
    """

    name: str
    prep: np.ndarray
    stroke: np.ndarray
    stroke_s: float = 0.22
    hold_s: float = 0.15
    channel: str = "arms"
    shake_hz: float = 0.0
    hand: str = "both"
    size: str = "medium"
    kind: str = "beat"
    priority: int = 1
    frequency: float = 0.0
    triggers: tuple[str, ...] = ()
    meaning: str = ""
    source: str = ""


def _choice(where: str, v: object, options: tuple[str, ...]) -> str:
    if v not in options:
        raise ConfigError(f"{where}: {v!r} is not one of {', '.join(options)}")
    return str(v)


def _number(where: str, v: object, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= float(v) <= hi:
        raise ConfigError(f"{where}: {v!r} must be a number in [{lo:g}, {hi:g}]")
    return float(v)


def _pose(where: str, v: object) -> np.ndarray:
    if v is None:
        v = {}
    if not isinstance(v, dict):
        raise ConfigError(f"{where}: must be a mapping of pose angle -> radians, e.g. {{r_elbow: 0.3}}")
    for k, a in v.items():
        _number(f"{where}.{k}", a, -3.2, 3.2)
    try:
        return pose(**{str(k): float(a) for k, a in v.items()})
    except KeyError as e:
        bad = str(e.args[0]).split("'")[1] if "'" in str(e.args[0]) else str(e.args[0])
        raise ConfigError(
            f"{where}.{bad}: unknown pose angle; use one of {', '.join(DOF_NAMES)} or both_<arm angle>"
        ) from None


def parse_unit(name: str, d: object, path: str) -> GestureUnit:
    """One unit from its YAML mapping; ConfigError naming ``path`` and the key on any mistake."""
    where = f"{path}: key units.{name}"
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: must be a mapping with at least prep and stroke")
    unknown = sorted(set(map(str, d)) - _KEYS)
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}: unknown key; use {', '.join(sorted(_KEYS))}")
    if "stroke" not in d:
        raise ConfigError(f"{where}.stroke: missing; give the stroke's end pose, e.g. {{r_elbow: -0.2}}")
    channel = _choice(f"{where}.channel", d.get("channel", "arms"), ("arms", "head"))
    triggers = d.get("triggers", [])
    if not isinstance(triggers, list) or not all(isinstance(t, str) and t.strip() for t in triggers):
        raise ConfigError(
            f"{where}.triggers: must be a list of words, e.g. [hello, hi] (quote words YAML reads as true/false: "
            '"no", "yes", "on", "off")'
        )
    u = GestureUnit(
        name=str(name),
        prep=_pose(f"{where}.prep", d.get("prep", {})),
        stroke=_pose(f"{where}.stroke", d["stroke"]),
        stroke_s=_number(f"{where}.stroke_s", d.get("stroke_s", 0.22), 0.05, 2.0),
        hold_s=_number(f"{where}.hold_s", d.get("hold_s", 0.15), 0.0, 3.0),
        channel=channel,
        shake_hz=_number(f"{where}.shake_hz", d.get("shake_hz", 0.0), 0.0, 6.0),
        hand=_choice(f"{where}.hand", d.get("hand", "none" if channel == "head" else "both"),
                     ("right", "left", "both", "none")),
        size=_choice(f"{where}.size", d.get("size", "medium"), tuple(SIZE_LEVEL)),
        kind=_choice(f"{where}.kind", d.get("kind", "semantic" if triggers else "beat"), ("beat", "semantic")),
        priority=int(_number(f"{where}.priority", d.get("priority", 1), 0, 100)),
        frequency=_number(f"{where}.frequency", d.get("frequency", 0.0), 0.0, 1.0),
        triggers=tuple(t.strip().lower() for t in triggers),
        meaning=str(d.get("meaning", "")),
        source=path,
    )  # fmt: skip
    if u.channel == "head" and np.any(np.delete(np.stack([u.prep, u.stroke]), _HEAD_IDX, axis=1)):
        raise ConfigError(f"{where}.stroke: a head unit may only move head_pitch, head_yaw, head_roll")
    return u


#: Largest gesture file read, bytes (the built-in repertoire is about 20 kB).
MAX_GESTURE_FILE_BYTES = 4 * 1024**2

_HEAD_IDX = [DOF_NAMES.index(n) for n in ("head_pitch", "head_yaw", "head_roll")]


def load_file(path: Path) -> dict[str, GestureUnit]:
    """Units of one YAML file."""
    try:
        data = load_yaml(read_text_capped(path, MAX_GESTURE_FILE_BYTES, "gesture file"))
    except InputError as e:  # missing, not a regular file, too large, not UTF-8
        raise ConfigError(str(e)) from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where} ({str(e).splitlines()[0]})") from None
    if not isinstance(data, dict) or not isinstance(data.get("units"), dict):
        raise ConfigError(f"{path}: key units: missing; a gesture file is a mapping 'units: {{name: {{...}}}}'")
    return {str(n): parse_unit(str(n), d, str(path)) for n, d in data["units"].items()}


def search_path() -> list[Path]:
    """``$ROBOGEST_GESTURES`` folders (or files) first, then the built-in folder."""
    extra = [Path(p) for p in os.environ.get("ROBOGEST_GESTURES", "").split(os.pathsep) if p]
    return [*extra, BUILTIN_DIR]


@lru_cache(maxsize=8)
def _load(paths: tuple[Path, ...]) -> dict[str, GestureUnit]:
    found: dict[str, GestureUnit] = {}
    for d in reversed(paths):  # later (built-in) first, so earlier folders replace units by name
        if d.is_file():
            files = [d]
        elif d.is_dir():
            files = sorted([*d.glob("*.yaml"), *d.glob("*.yml")])
        else:
            raise ConfigError(f"{d}: gesture folder not found (from ROBOGEST_GESTURES); fix or unset it")
        for f in files:
            found.update(load_file(f))
    return found


def load_units(paths: list[Path] | None = None) -> dict[str, GestureUnit]:
    """All units on the search path (or ``paths``), by name."""
    return dict(_load(tuple(search_path() if paths is None else paths)))


@dataclass(frozen=True)
class Repertoire:
    """The units a generator uses, with the lookups it needs."""

    units: dict[str, GestureUnit]

    @property
    def beat_units(self) -> tuple[str, ...]:
        """Arm units the statistical interpreter draws from (``kind: beat``, ``frequency`` > 0)."""
        return tuple(n for n, u in self.units.items() if u.channel == "arms" and u.kind == "beat" and u.frequency > 0)

    def keywords(self) -> dict[str, list[str]]:
        """Trigger word or phrase -> units, highest priority first."""
        out: dict[str, list[str]] = {}
        for n, u in self.units.items():
            for t in u.triggers:
                out.setdefault(t, []).append(n)
        for t in out:
            out[t].sort(key=lambda n: -self.units[n].priority)
        return out

    def next_beat_unit(
        self, counts: np.ndarray, prominence: float, rng: np.random.Generator, avoid: frozenset[str] = frozenset()
    ) -> int:
        """Statistical interpreter, Rhythmic Gesticulator eq. 24, plus a size bias and no repeats.

        ``p ∝ softmax(f^I - f_t) ⊙ size_bias``: units used less than their target frequency so far become
        more likely and louder beats prefer larger units; units in ``avoid`` (used within the last 10 s
        just before) are left out unless nothing else remains.

        Parameters
        ----------
        counts : ndarray [shape=(N,)]
            How often each of :attr:`beat_units` has been used so far.
        prominence : float
            Beat prominence in [0, 1].
        """
        names = self.beat_units
        freq = np.array([self.units[n].frequency for n in names])
        freq = freq / freq.sum()
        f_t = counts / counts.sum() if counts.sum() > 0 else np.zeros_like(freq)
        z = 8.0 * (freq - f_t)
        soft = np.exp(z - z.max())
        size = np.array([SIZE_LEVEL[self.units[n].size] for n in names])
        p = soft * freq * np.exp(-((size - prominence) ** 2) / (2 * 0.3**2))
        mask = np.array([n not in avoid for n in names])
        if mask.any():
            p = p * mask
        p /= p.sum()
        return int(rng.choice(len(names), p=p))


def default_repertoire() -> Repertoire:
    return Repertoire(load_units())


def repertoire_with(path: Path) -> Repertoire:
    """The units on the search path plus those of ``path`` (a folder or YAML file of units), which replace units
    of the same name: what ``--gestures PATH`` and a per-call ``gestures`` path give the generator."""
    return Repertoire(load_units([path, *search_path()]))
