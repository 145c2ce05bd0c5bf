"""Joint limits and safety settings, validated once so the stages can trust them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import ConfigError, InputError
from robogest.robot.config import LIMIT_MARGIN_RAD

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig


def _joint_list(idx: np.ndarray, names: tuple[str, ...]) -> str:
    ids = [int(i) for i in np.atleast_1d(idx)]
    if names:
        return ", ".join(f"{names[i]!r} (#{i})" for i in ids)
    return ", ".join(f"#{i}" for i in ids)


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Per-joint limits the safety layer enforces.

    Attributes
    ----------
    q_min_rad, q_max_rad : ndarray [shape=(J,)], radians
        Hard position limits, ``q_min < q_max``.
    v_max_rad_s : ndarray [shape=(J,)], rad/s
        Velocity limit, ``> 0``.
    a_max_rad_s2 : ndarray [shape=(J,)], rad/s²
        Acceleration limit, ``> 0``.
    rest_q_rad : ndarray [shape=(J,)], radians
        Rest pose, inside ``[q_min, q_max]``. Treated as safe even when it lies inside the margin.
    names : tuple of str, length J or 0
        Joint names, used only in error messages.
    held_mask : ndarray [shape=(J,)], bool, optional
        Joints held at their rest angle (a humanoid's legs: :attr:`~robogest.robot.config.JointConfig.held`):
        their position band is the rest angle alone, so every stage pins them there. Default: none.
    """

    q_min_rad: np.ndarray
    q_max_rad: np.ndarray
    v_max_rad_s: np.ndarray
    a_max_rad_s2: np.ndarray
    rest_q_rad: np.ndarray
    names: tuple[str, ...] = field(default=())
    held_mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        keys = ("q_min_rad", "q_max_rad", "v_max_rad_s", "a_max_rad_s2", "rest_q_rad")
        arrays = {}
        for k in keys:
            try:
                a = np.array(getattr(self, k), dtype=float)  # a private copy: callers cannot mutate us
            except (TypeError, ValueError):
                raise InputError(f"JointLimits.{k}: not a numeric array") from None
            if a.ndim != 1 or a.size == 0:
                raise InputError(f"JointLimits.{k}: expected a non-empty 1-D array, got shape {a.shape}")
            a.setflags(write=False)
            arrays[k] = a
        n = arrays["q_min_rad"].size
        bad_shape = [k for k in keys if arrays[k].size != n]
        if bad_shape:
            raise InputError(f"JointLimits: {bad_shape} do not have the {n} joints q_min_rad has")
        names = tuple(str(s) for s in self.names)
        if names and len(names) != n:
            raise InputError(f"JointLimits.names has {len(names)} names for {n} joints")
        for k in keys:
            bad = np.flatnonzero(~np.isfinite(arrays[k]))
            if bad.size:
                raise InputError(f"JointLimits.{k} is not finite for joints {_joint_list(bad, names)}")
        checks = (
            (arrays["q_min_rad"] >= arrays["q_max_rad"], "q_min_rad must be below q_max_rad"),
            (arrays["v_max_rad_s"] <= 0, "v_max_rad_s must be > 0"),
            (arrays["a_max_rad_s2"] <= 0, "a_max_rad_s2 must be > 0"),
            (
                (arrays["rest_q_rad"] < arrays["q_min_rad"]) | (arrays["rest_q_rad"] > arrays["q_max_rad"]),
                "rest_q_rad must lie within [q_min_rad, q_max_rad]",
            ),
        )
        for bad_mask, msg in checks:
            bad = np.flatnonzero(bad_mask)
            if bad.size:
                raise InputError(f"JointLimits: {msg}; violated by joints {_joint_list(bad, names)}")
        held = np.zeros(n, dtype=bool) if self.held_mask is None else np.array(self.held_mask, dtype=bool)
        if held.shape != (n,):
            raise InputError(f"JointLimits.held_mask has shape {held.shape}; expected ({n},)")
        held.setflags(write=False)
        for k, a in arrays.items():
            object.__setattr__(self, k, a)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "held_mask", held)

    @property
    def n_joints(self) -> int:
        return int(self.q_min_rad.size)

    @classmethod
    def from_robot(cls, robot: RobotConfig) -> JointLimits:
        """Limits of a validated :class:`~robogest.robot.config.RobotConfig`, in its joint order."""
        return cls(
            q_min_rad=robot.q_min_rad,
            q_max_rad=robot.q_max_rad,
            v_max_rad_s=robot.v_max_rad_s,
            a_max_rad_s2=robot.a_max_rad_s2,
            rest_q_rad=robot.rest_q_rad,
            names=tuple(robot.joint_names),
            held_mask=robot.held_mask,
        )

    def band(self, margin_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """Position band ``[q_min + margin, q_max - margin]``; a range narrower than ``2·margin`` gives its midpoint,
        a held joint its rest angle (every stage clamps into this band, so none moves a held joint).

        Returns
        -------
        lo, hi : ndarray [shape=(J,)], radians
        """
        lo = self.q_min_rad + margin_rad
        hi = self.q_max_rad - margin_rad
        mid = 0.5 * (self.q_min_rad + self.q_max_rad)
        narrow = lo > hi
        lo, hi = np.where(narrow, mid, lo), np.where(narrow, mid, hi)
        held = np.zeros(self.n_joints, dtype=bool) if self.held_mask is None else self.held_mask  # set by __post_init__
        return np.where(held, self.rest_q_rad, lo), np.where(held, self.rest_q_rad, hi)


def opencv_sigma(kernel: int) -> float:
    """Default Gaussian sigma (frames) for a kernel size: OpenCV's ``getGaussianKernel(k, 0)`` rule.

    ``0.3·((k − 1)/2 − 1) + 0.8`` (1.1 frames for k = 5); "kernel size k" in papers usually means this kernel.
    """
    return 0.3 * ((kernel - 1) * 0.5 - 1.0) + 0.8


@dataclass(frozen=True)
class SafetyConfig:
    """Settings of :func:`~robogest.safety.apply_safety`.

    Attributes
    ----------
    margin_rad : float, radians
        Commands stay this far inside each position limit (the midpoint if the range is narrower than twice this).
    smooth_kernel : int, frames
        Gaussian kernel size along time, odd and ≥ 1; 1 switches smoothing off (Rhythmic Gesticulator §7.1.2: 5).
    smooth_sigma : float or None, frames
        Gaussian sigma; None uses OpenCV's rule for the kernel size (:func:`opencv_sigma`, 1.1 frames for 5).
    rest_after_s : float, seconds
        Silent periods at least this long send the robot to rest and hold it there.
    rest_leave_s : float, seconds
        The robot may leave rest this long before such a silent period ends, to be in place for the next stroke.
    start_from_rest : bool
        With no ``q0`` given, assume the robot is at rest (True) or already at the first target frame (False,
        for simulation only: a real robot elsewhere would jump).
    preview : bool
        Fit the targets within the velocity and acceleration limits over the whole trajectory before tracking
        (:func:`~robogest.safety.stages.fit_within_limits`), so moves too fast for the robot are centred on their
        targets instead of falling behind them. False tracks the rate-limited targets causally, as a live
        stream must.
    """

    margin_rad: float = LIMIT_MARGIN_RAD
    smooth_kernel: int = 5
    smooth_sigma: float | None = None
    rest_after_s: float = 1.0
    rest_leave_s: float = 0.4
    start_from_rest: bool = True
    preview: bool = True

    def __post_init__(self) -> None:
        def finite(x: object) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

        if not finite(self.margin_rad) or self.margin_rad < 0:
            raise ConfigError(f"SafetyConfig.margin_rad must be a finite number ≥ 0, got {self.margin_rad!r}")
        k = self.smooth_kernel
        if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k < 1 or k % 2 == 0:
            raise ConfigError(f"SafetyConfig.smooth_kernel must be an odd integer ≥ 1 (1 = off), got {k!r}")
        if self.smooth_sigma is not None and (not finite(self.smooth_sigma) or self.smooth_sigma <= 0):
            raise ConfigError(f"SafetyConfig.smooth_sigma must be None or a number > 0, got {self.smooth_sigma!r}")
        if not finite(self.rest_after_s) or self.rest_after_s <= 0:
            raise ConfigError(f"SafetyConfig.rest_after_s must be a number > 0, got {self.rest_after_s!r}")
        if not finite(self.rest_leave_s) or self.rest_leave_s < 0:
            raise ConfigError(f"SafetyConfig.rest_leave_s must be a number ≥ 0, got {self.rest_leave_s!r}")
