"""The command trajectory: what leaves the safety layer and what every backend plays."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path, read_npz

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig

_ARRAY_KEYS = ("t_s", "q_rad", "q_min_rad", "q_max_rad", "v_max_rad_s", "a_max_rad_s2", "rest_q_rad", "silent")
#: Per-joint limits a trajectory carries, and the :class:`RobotConfig` property each must equal.
_LIMIT_KEYS = ("q_min_rad", "q_max_rad", "v_max_rad_s", "a_max_rad_s2", "rest_q_rad")


@dataclass(eq=False)
class Trajectory:
    """Joint commands sampled at a fixed rate, with the limits they were made to satisfy.

    Attributes
    ----------
    t_s : ndarray [shape=(T,)], seconds
        Sample times, ``t_s[k] = k / fps``.
    q_rad : ndarray [shape=(T, J)], radians
        Joint position commands.
    joint_names : list of str, length J
    q_min_rad, q_max_rad, v_max_rad_s, a_max_rad_s2, rest_q_rad : ndarray [shape=(J,)]
        Position limits (rad), velocity limit (rad/s), acceleration limit (rad/s²), rest pose (rad).
    silent : ndarray [shape=(T,)], bool
        Sample lies inside a silent period long enough to hold rest.
    audio_path : str
        The speech audio this trajectory goes with ("" if none).
    robot : str
        Robot name.
    annotations : dict of str to ndarray
        Numeric arrays the generator left for evaluation (e.g. ``lexemes``, ``n_lexemes`` of the Rhythmic
        Gesticulator); saved as ``annotation_<name>``.
    """

    t_s: np.ndarray
    q_rad: np.ndarray
    joint_names: list[str]
    q_min_rad: np.ndarray
    q_max_rad: np.ndarray
    v_max_rad_s: np.ndarray
    a_max_rad_s2: np.ndarray
    rest_q_rad: np.ndarray
    silent: np.ndarray
    audio_path: str = ""
    robot: str = ""
    annotations: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t, j = self.q_rad.shape
        if self.t_s.shape != (t,) or self.silent.shape != (t,) or len(self.joint_names) != j:
            raise ValueError("t_s, silent and joint_names must match q_rad's (T, J) shape")

    @classmethod
    def for_robot(
        cls,
        robot: RobotConfig,
        q_rad: np.ndarray,
        fps: float | None = None,
        *,
        t_s: np.ndarray | None = None,
        silent: np.ndarray | None = None,
        audio_path: str = "",
    ) -> Trajectory:
        """Commands ``q_rad`` [shape=(T, J), rad] for ``robot``, with its joint names, limits, rest pose and name
        (the block :func:`check_matches` compares, so it is copied in one place only).

        Times are ``t_s`` [shape=(T,), s] if given, else ``k / fps``; ``silent`` [shape=(T,), bool] defaults to
        all False (no rest windows).
        """
        n = len(q_rad)
        if t_s is None and fps is not None:
            times = np.arange(n) / fps
        elif t_s is not None and fps is None:
            times = t_s
        else:
            raise ValueError("Trajectory.for_robot needs exactly one of fps and t_s")
        return cls(
            t_s=times,
            q_rad=q_rad,
            joint_names=robot.joint_names,
            q_min_rad=robot.q_min_rad,
            q_max_rad=robot.q_max_rad,
            v_max_rad_s=robot.v_max_rad_s,
            a_max_rad_s2=robot.a_max_rad_s2,
            rest_q_rad=robot.rest_q_rad,
            silent=np.zeros(n, dtype=bool) if silent is None else silent,
            audio_path=audio_path,
            robot=robot.name,
        )

    @property
    def n_frames(self) -> int:
        return int(self.q_rad.shape[0])

    @property
    def fps(self) -> float:
        if self.n_frames < 2:
            return 1.0
        return float(1.0 / np.median(np.diff(self.t_s)))

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1]) if self.n_frames else 0.0

    def sample(self, t_s: float) -> np.ndarray:
        """Linearly interpolated command ``(J,)`` at time ``t_s`` (held at the ends)."""
        if self.n_frames == 0:
            return np.array(self.rest_q_rad, dtype=float)
        k = float(np.clip(t_s * self.fps, 0, self.n_frames - 1))
        i0 = int(np.floor(k))
        i1 = min(i0 + 1, self.n_frames - 1)
        w = k - i0
        return np.asarray((1 - w) * self.q_rad[i0] + w * self.q_rad[i1], dtype=float)

    def sample_velocity(self, t_s: float) -> np.ndarray:
        """Velocity ``(J,)`` rad/s of :meth:`sample` at ``t_s``: the slope of the segment there (0 at the ends)."""
        if self.n_frames < 2 or t_s < 0 or t_s >= self.duration_s:
            return np.zeros(self.q_rad.shape[1])
        i0 = min(int(np.floor(t_s * self.fps)), self.n_frames - 2)
        return np.asarray((self.q_rad[i0 + 1] - self.q_rad[i0]) * self.fps, dtype=float)

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` atomically (a crash never leaves a half-written file)."""
        arrays = {k: getattr(self, k) for k in _ARRAY_KEYS}
        arrays["joint_names"] = np.array(self.joint_names)
        arrays["audio_path"] = np.array(self.audio_path)
        arrays["robot"] = np.array(self.robot)
        arrays.update({f"{ANNOTATION_PREFIX}{k}": np.asarray(v) for k, v in self.annotations.items()})
        with atomic_path(path, ".npz") as tmp:
            np.savez(tmp, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a file written by :meth:`save`, refusing anything that could not have come from it.

        Refused with one :class:`InputError` line naming the file: pickled objects, text where numbers belong,
        shapes that do not match ``q_rad``'s ``(T, J)``, time stamps that are not finite, do not start at 0,
        do not increase by one fixed step, imply a rate outside :data:`FPS_RANGE_HZ` or last longer than
        :data:`MAX_DURATION_S` (a play that would run for ever).
        """
        path = Path(path)
        z = read_npz(path, what="trajectory")
        missing = [k for k in (*_ARRAY_KEYS, "joint_names") if k not in z]
        if missing:
            raise InputError(f"{path}: not a robogest trajectory (missing keys {missing})")
        q = _numbers(z, "q_rad", None, path)
        if q.ndim != 2 or q.shape[0] < 1 or q.shape[1] < 1:
            raise InputError(f"{path}: q_rad must be (T, J) with T, J >= 1, got shape {q.shape}")
        n, j = q.shape
        names = z["joint_names"]
        if names.dtype.kind != "U" or names.shape != (j,):
            raise InputError(f"{path}: joint_names must be {j} strings (one per q_rad column), got {names.dtype} "
                             f"{names.shape}")  # fmt: skip
        kw = {k: _numbers(z, k, (j,), path) for k in _ARRAY_KEYS[2:7]}
        t = _numbers(z, "t_s", (n,), path, finite=True)
        check_time_stamps(t, path)
        silent = _numbers(z, "silent", (n,), path)
        text = {}
        for key in ("audio_path", "robot"):
            v = z.get(key, np.array(""))
            if v.dtype.kind != "U" or v.ndim != 0:
                raise InputError(f"{path}: {key} must be one string, got {v.dtype} {v.shape}")
            text[key] = str(v)
        notes = {
            k.removeprefix(ANNOTATION_PREFIX): _numbers(z, k, None, path) for k in z if k.startswith(ANNOTATION_PREFIX)
        }
        return cls(
            t_s=t, q_rad=q, joint_names=[str(s) for s in names], q_min_rad=kw["q_min_rad"],
            q_max_rad=kw["q_max_rad"], v_max_rad_s=kw["v_max_rad_s"], a_max_rad_s2=kw["a_max_rad_s2"],
            rest_q_rad=kw["rest_q_rad"], silent=silent != 0, audio_path=text["audio_path"], robot=text["robot"],
            annotations=notes,
        )  # fmt: skip


def saved_audio_path(path: str | Path) -> str:
    """The ``audio_path`` a saved trajectory names, read alone (one small member, not the whole file); "" when it
    names none or holds something other than one string. An unreadable file is an :class:`InputError`."""
    v = read_npz(path, keys=["audio_path"]).get("audio_path")
    return str(v) if v is not None and v.dtype.kind == "U" and v.ndim == 0 else ""


#: Key prefix of :attr:`Trajectory.annotations` in a saved ``.npz``.
ANNOTATION_PREFIX = "annotation_"
#: Longest trajectory robogest loads (and so plays), seconds.
MAX_DURATION_S = 24 * 3600.0
#: Sample rates a trajectory may have, Hz (the range ``--fps`` accepts).
FPS_RANGE_HZ = (1.0, 1000.0)


def _numbers(
    z: dict[str, np.ndarray], key: str, shape: tuple[int, ...] | None, path: Path, finite: bool = False
) -> np.ndarray:
    """``z[key]`` as float64 (bool stays bool) of ``shape`` (None: any), or an InputError naming the key.

    Only ``finite`` arrays are checked for NaN/inf here; commands and limits are judged against the robot by
    :func:`check_matches`, which names the joint and sample.
    """
    a = z[key]
    if a.dtype.kind not in "biuf":
        raise InputError(f"{path}: {key} holds {a.dtype} values, not numbers; not a robogest trajectory")
    if shape is not None and a.shape != shape:
        raise InputError(f"{path}: {key} has shape {a.shape}, expected {shape} to match q_rad")
    if a.dtype.kind == "b":
        return np.array(a, dtype=bool)
    a = a.astype(np.float64)
    if finite and not np.isfinite(a).all():
        k = int(np.flatnonzero(~np.isfinite(a.reshape(-1)))[0])
        raise InputError(f"{path}: {key} holds NaN or inf (first at flat index {k}); the file is corrupt")
    return a


def check_time_stamps(t_s: np.ndarray, path: str | Path) -> None:
    """Refuse sample times ``(T,)`` s that are not ``k / fps`` for a sane ``fps`` and a sane length."""
    if len(t_s) and abs(t_s[0]) > 1e-9:
        raise InputError(f"{path}: time stamps must start at 0 s, t_s[0] = {t_s[0]:g} s")
    if len(t_s) < 2:
        return
    dt = np.diff(t_s)
    if not (dt > 0).all():
        k = int(np.flatnonzero(dt <= 0)[0])
        raise InputError(f"{path}: time stamps must increase, t_s[{k + 1}] = {t_s[k + 1]:g} s follows {t_s[k]:g} s")
    step = float(np.median(dt))
    if np.abs(dt - step).max() > 1e-3 * step:
        raise InputError(f"{path}: time stamps must be evenly spaced (one command rate); resample the trajectory")
    lo, hi = FPS_RANGE_HZ
    if not lo <= 1.0 / step <= hi:
        raise InputError(f"{path}: sample rate {1.0 / step:g} Hz is outside {lo:g}..{hi:g} Hz")
    if t_s[-1] > MAX_DURATION_S:
        raise InputError(f"{path}: lasts {t_s[-1]:g} s, longer than the {MAX_DURATION_S:g} s robogest plays; split it")


def check_matches(trajectory: Trajectory, robot: RobotConfig, where: str = "") -> None:
    """Refuse a trajectory whose joints, limits or rest pose differ from the robot definition's.

    Limits always come from the robot; the copies a trajectory (file) carries must agree with them exactly, so
    a file made for another robot, an edited or a corrupt one is never played. The commands must be finite.

    Parameters
    ----------
    trajectory : Trajectory
    robot : RobotConfig
    where : str
        The file name, for the message (default: "trajectory").

    Raises
    ------
    InputError
        Naming the first differing key and joint, and how to fix it.
    """
    where = where or "trajectory"
    fix = f"regenerate it for {robot.name} (robogest speak ... --robot {robot.name} --save FILE)"
    if list(trajectory.joint_names) != robot.joint_names:
        raise InputError(
            f"{where}: joints {list(trajectory.joint_names)} differ from robot {robot.name}'s {robot.joint_names}; "
            f"pass the --robot it was made for ({trajectory.robot or 'unknown'}), or {fix}"
        )
    for key in _LIMIT_KEYS:
        mine = np.asarray(getattr(robot, key), dtype=float)
        try:
            theirs = np.asarray(getattr(trajectory, key), dtype=float).reshape(mine.shape)
        except (TypeError, ValueError):
            raise InputError(f"{where}: key {key} is not {mine.size} numbers, one per joint; {fix}") from None
        same = np.isclose(theirs, mine, rtol=1e-9, atol=1e-12)
        if not same.all():
            j = int(np.flatnonzero(~same)[0])
            raise InputError(
                f"{where}: key {key} of joint {robot.joint_names[j]} is {float(theirs[j])!r} but {float(mine[j])!r} "
                f"in robot {robot.name}'s definition (limits come from the robot, never the file); {fix}"
            )
    bad = ~np.isfinite(np.asarray(trajectory.q_rad, dtype=float))
    if bad.any():
        k, j = (int(i) for i in np.argwhere(bad)[0])
        raise InputError(
            f"{where}: command q_rad[{k}] of joint {robot.joint_names[j]} is {float(trajectory.q_rad[k, j])!r}, "
            f"not a finite angle ({int(bad.sum())} such values); {fix}"
        )
