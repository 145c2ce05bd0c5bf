"""The command trajectory: what leaves the safety layer and what every backend plays."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path

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

    def __post_init__(self) -> None:
        t, j = self.q_rad.shape
        if self.t_s.shape != (t,) or self.silent.shape != (t,) or len(self.joint_names) != j:
            raise ValueError("t_s, silent and joint_names must match q_rad's (T, J) shape")

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
            return self.rest_q_rad.copy()
        k = float(np.clip(t_s * self.fps, 0, self.n_frames - 1))
        i0 = int(np.floor(k))
        i1 = min(i0 + 1, self.n_frames - 1)
        w = k - i0
        return (1 - w) * self.q_rad[i0] + w * self.q_rad[i1]

    def sample_velocity(self, t_s: float) -> np.ndarray:
        """Velocity ``(J,)`` rad/s of :meth:`sample` at ``t_s``: the slope of the segment there (0 at the ends)."""
        if self.n_frames < 2 or t_s < 0 or t_s >= self.duration_s:
            return np.zeros(self.q_rad.shape[1])
        i0 = min(int(np.floor(t_s * self.fps)), self.n_frames - 2)
        return (self.q_rad[i0 + 1] - self.q_rad[i0]) * self.fps

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` atomically (a crash never leaves a half-written file)."""
        arrays = {k: getattr(self, k) for k in _ARRAY_KEYS}
        arrays["joint_names"] = np.array(self.joint_names)
        arrays["audio_path"] = np.array(self.audio_path)
        arrays["robot"] = np.array(self.robot)
        with atomic_path(path, ".npz") as tmp:
            np.savez(tmp, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = [k for k in (*_ARRAY_KEYS, "joint_names") if k not in z]
                if missing:
                    raise InputError(f"{path}: not a robogest trajectory (missing keys {missing})")
                kw = {k: np.array(z[k]) for k in _ARRAY_KEYS}
                return cls(
                    joint_names=[str(s) for s in z["joint_names"]],
                    audio_path=str(z["audio_path"]) if "audio_path" in z else "",
                    robot=str(z["robot"]) if "robot" in z else "",
                    **kw,
                )
        except (OSError, ValueError) as e:
            raise InputError(f"{path}: cannot read trajectory ({e})") from None


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
