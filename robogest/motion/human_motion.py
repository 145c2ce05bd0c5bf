"""``HumanMotion``: a skeleton moving over time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robogest.errors import InputError
from robogest.motion import rotations as R
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M, Skeleton

#: Motion files robogest reads: frame rates, Hz, and the longest take, seconds. Beyond these a file is broken or
#: crafted, and resampling it to the command rate would allocate without bound.
FPS_RANGE_HZ = (1.0, 1000.0)
MAX_DURATION_S = 24 * 3600.0


def check_take(n_frames: int, fps: float, source: str) -> None:
    """Refuse a motion file whose frame rate or length (``n_frames / fps`` s) is absurd; ``source`` names it."""
    lo, hi = FPS_RANGE_HZ
    if not lo <= fps <= hi:
        raise InputError(f"{source}: frame rate {fps:g} fps is outside {lo:g}..{hi:g}; fix the file's frame rate")
    if n_frames / fps > MAX_DURATION_S:
        raise InputError(
            f"{source}: {n_frames} frames at {fps:g} fps last {n_frames / fps:.0f} s, longer than the "
            f"{MAX_DURATION_S:.0f} s robogest reads; split the take"
        )


@dataclass(eq=False)
class HumanMotion:
    """Local joint rotations and root translation at a fixed frame rate.

    Attributes
    ----------
    fps : float
        Frames per second.
    rotations : ndarray [shape=(T, J, 4)]
        Local unit quaternions (w, x, y, z) relative to the skeleton's rest pose.
    root_pos_m : ndarray [shape=(T, 3)], metres
        Root (pelvis) position in the world.
    skeleton : Skeleton
        Usually :data:`CANONICAL`.
    """

    fps: float
    rotations: np.ndarray
    root_pos_m: np.ndarray
    skeleton: Skeleton = field(default=CANONICAL)

    def __post_init__(self) -> None:
        self.rotations = np.asarray(self.rotations, dtype=np.float64)
        self.root_pos_m = np.asarray(self.root_pos_m, dtype=np.float64)
        t, j = self.rotations.shape[:2]
        if self.rotations.shape != (t, j, 4) or j != self.skeleton.n_joints:
            raise ValueError(f"rotations must be (T, {self.skeleton.n_joints}, 4), got {self.rotations.shape}")
        if self.root_pos_m.shape != (t, 3):
            raise ValueError(f"root_pos_m must be ({t}, 3), got {self.root_pos_m.shape}")
        if not self.fps > 0:
            raise InputError(f"motion frame rate must be positive, got {self.fps}")
        if not (np.isfinite(self.rotations).all() and np.isfinite(self.root_pos_m).all()):
            raise InputError("motion contains NaN or infinite values")

    @classmethod
    def rest(cls, n_frames: int, fps: float, skeleton: Skeleton = CANONICAL) -> HumanMotion:
        """Identity rotations (T-pose) with the pelvis at its canonical height."""
        rot = np.broadcast_to(R.IDENTITY, (n_frames, skeleton.n_joints, 4)).copy()
        root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (n_frames, 1))
        return cls(fps=fps, rotations=rot, root_pos_m=root, skeleton=skeleton)

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    @property
    def t_s(self) -> np.ndarray:
        """Frame times, ``(T,)`` seconds."""
        return np.arange(self.n_frames) / self.fps

    def positions(self) -> np.ndarray:
        """Joint positions ``(T, J, 3)`` in metres, by forward kinematics."""
        return self.skeleton.forward_kinematics(self.rotations, self.root_pos_m)

    def resample(self, fps: float, n_frames: int | None = None) -> HumanMotion:
        """Same motion at another frame rate (slerp for rotations, linear for the root).

        ``n_frames`` makes the result exactly that long (a generator's output must match its speech frame for
        frame, and rate conversion rounds): missing frames hold the last one, extra frames are dropped.
        """
        out = self._resample(fps)
        if n_frames is None or out.n_frames == n_frames:
            return out
        idx = np.minimum(np.arange(n_frames), max(out.n_frames - 1, 0))  # (n_frames,) pad by holding the last
        return HumanMotion(fps, out.rotations[idx], out.root_pos_m[idx], out.skeleton)

    def _resample(self, fps: float) -> HumanMotion:
        if not fps > 0:
            raise InputError(f"target frame rate must be positive, got {fps}")
        if self.n_frames < 2 or fps == self.fps:
            return HumanMotion(fps, self.rotations.copy(), self.root_pos_m.copy(), self.skeleton)
        n_out = max(1, round(self.duration_s * fps))
        src = np.arange(n_out) * (self.fps / fps)  # (T_out,) fractional source frame
        i0 = np.clip(np.floor(src).astype(int), 0, self.n_frames - 1)
        i1 = np.clip(i0 + 1, 0, self.n_frames - 1)
        w = (src - i0)[:, None]  # (T_out, 1)
        rot = R.slerp(self.rotations[i0], self.rotations[i1], np.broadcast_to(w, (n_out, self.skeleton.n_joints)))
        root = (1 - w) * self.root_pos_m[i0] + w * self.root_pos_m[i1]
        return HumanMotion(fps, rot, root, self.skeleton)
