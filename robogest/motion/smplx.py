"""SMPL-X / SMPL-H / SMPL parameter files (``.npz``: BEAT2/EMAGE, AMASS) onto :data:`CANONICAL`, and back.

SMPL-family rest poses are a T-pose, Y up, facing +Z, +X = the body's left, which is the canonical convention, and the
upper-body chain (pelvis, spine1-3, neck, head, collars, shoulders, elbows, wrists) has exactly the canonical
topology, so local rotations copy over joint for joint. Legs, jaw, eyes and fingers are leaves from the canonical
skeleton's point of view and are dropped. The body model file is not needed: bone lengths come from
:data:`CANONICAL`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path, npz_keys, read_npz
from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion, check_take
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M

#: Canonical joint -> SMPL(-X/-H) joint index (the first 22 joints are shared by the three models).
SMPLX_INDEX: dict[str, int] = {
    "pelvis": 0,
    "spine": 3,
    "spine1": 6,
    "spine2": 9,
    "neck": 12,
    "head": 15,
    "l_collar": 13,
    "l_shoulder": 16,
    "l_elbow": 18,
    "l_wrist": 20,
    "r_collar": 14,
    "r_shoulder": 17,
    "r_elbow": 19,
    "r_wrist": 21,
}
#: Pelvis joint of the neutral SMPL-X template relative to the model origin (what ``trans`` moves), metres.
SMPLX_PELVIS_OFFSET_M = np.array([0.0, -0.35, 0.0])
#: Pelvis height above the floor of a standing SMPL-X body, metres; scaled to ``CANONICAL_PELVIS_HEIGHT_M``.
SMPLX_PELVIS_HEIGHT_M = 0.94
_FPS_KEYS = ("mocap_frame_rate", "mocap_framerate", "fps", "frame_rate")


def _numbers(data: dict[str, np.ndarray], key: str, path: Path) -> np.ndarray:
    """``data[key]`` as float64, or an InputError naming the key when it holds text (or anything but numbers):
    string-typed poses were a traceback, and text such as ``"0.1"`` would have been read as numbers unseen."""
    a = np.asarray(data[key])
    if a.dtype.kind not in "iuf":
        raise InputError(f"{path}: '{key}' holds {a.dtype} values, not numbers; re-export the SMPL-X parameters")
    return a.astype(np.float64)


def _body_rotvecs(data: dict[str, np.ndarray], path: Path) -> np.ndarray:
    """Axis-angle ``(T, 22, 3)`` radians for the 22 body joints from ``poses`` or AMASS-style split keys."""
    if "poses" in data:
        poses = _numbers(data, "poses", path)
        if poses.ndim != 2 or poses.shape[1] % 3 or poses.shape[1] < 66:
            raise InputError(
                f"{path}: 'poses' must be (T, 3*J) axis-angle with J >= 22 joints (SMPL-X: 165), "
                f"got shape {poses.shape}. Export SMPL-X/SMPL-H/SMPL parameters."
            )
        return poses.reshape(poses.shape[0], poses.shape[1] // 3, 3)[:, :22]  # (T, J, 3) -> first 22 body joints
    if "root_orient" in data and "pose_body" in data:
        root = _numbers(data, "root_orient", path).reshape(-1, 1, 3)  # (T, 1, 3)
        body = _numbers(data, "pose_body", path)
        body = body.reshape(body.shape[0], -1, 3)[:, :21] if body.size else np.zeros((0, 21, 3))  # (T, 21, 3)
        if body.shape[1] != 21 or body.shape[0] != root.shape[0]:
            raise InputError(f"{path}: 'pose_body' must be (T, 63) matching 'root_orient' (T, 3)")
        return np.concatenate([root, body], axis=1)
    raise InputError(
        f"{path}: no 'poses' array (keys: {', '.join(sorted(npz_keys(path))) or 'none'}). Pass an SMPL-X/AMASS "
        "parameter .npz with 'poses' (T, 165) axis-angle, 'trans' (T, 3) and 'mocap_frame_rate'."
    )


def load_smplx(path: str | os.PathLike, fps: float | None = None) -> HumanMotion:
    """SMPL-X (or SMPL-H/SMPL, AMASS-style) parameters mapped onto :data:`CANONICAL`.

    Parameters
    ----------
    path : path-like
        ``.npz`` with ``poses`` ``(T, 3J)`` axis-angle radians in standard SMPL-X joint order (or AMASS
        ``root_orient`` + ``pose_body``), optional ``trans`` ``(T, 3)`` metres, and a frame rate
        (``mocap_frame_rate`` / ``mocap_framerate``).
    fps : float, optional
        Frame rate when the file has none (it overrides the file otherwise).

    Notes
    -----
    Z-up files (AMASS) are detected from the mean body up direction and rotated to Y up. The pelvis position is
    ``trans + SMPLX_PELVIS_OFFSET_M`` scaled by ``CANONICAL_PELVIS_HEIGHT_M / SMPLX_PELVIS_HEIGHT_M`` (the body-shape
    specific pelvis offset needs the model file, which is not used).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such SMPL-X file. Check the path.")
    # only what is used: an all-zero expressions or hands array, compressed, would look like a decompression bomb
    data = read_npz(path, what="SMPL-X", keys=("poses", "root_orient", "pose_body", "trans", *_FPS_KEYS))
    rotvec = _body_rotvecs(data, path)  # (T, 22, 3)
    n_frames = rotvec.shape[0]
    if n_frames == 0:
        raise InputError(f"{path}: the file has no frames")
    if fps is None:
        key = next((k for k in _FPS_KEYS if k in data), None)
        if key is None:
            raise InputError(f"{path}: no frame rate ({' / '.join(_FPS_KEYS)}). Pass fps= explicitly.")
        try:
            fps = float(_numbers(data, key, path).reshape(-1)[0])
        except IndexError:
            raise InputError(f"{path}: {key} is empty; it must be the frame rate") from None
    check_take(n_frames, fps, str(path))
    trans = _numbers(data, "trans", path) if "trans" in data else np.zeros((n_frames, 3))
    if trans.shape != (n_frames, 3):
        raise InputError(f"{path}: 'trans' must be ({n_frames}, 3), got {trans.shape}")
    if not (np.isfinite(rotvec).all() and np.isfinite(trans).all()):
        raise InputError(f"{path}: poses or trans contain NaN/inf. Re-export the file.")

    q = R.from_axis_angle(rotvec)  # (T, 22, 4) local rotations
    up = R.rotate(q[:, 0], np.array([0.0, 1.0, 0.0])).mean(axis=0)  # mean body up in the file's world
    axis_change = R.IDENTITY
    if abs(up[2]) > abs(up[1]):  # Z-up world (AMASS): rotate the world -90 deg about X so +Z becomes +Y
        axis_change = R.from_axis_angle(np.array([-np.pi / 2, 0.0, 0.0]))

    rot = np.broadcast_to(R.IDENTITY, (n_frames, CANONICAL.n_joints, 4)).copy()  # leaves (nose, hands) stay identity
    for name, i in SMPLX_INDEX.items():
        rot[:, CANONICAL.index(name)] = q[:, i]
    rot[:, CANONICAL.index("pelvis")] = R.mul(axis_change, q[:, 0])
    pelvis = R.rotate(axis_change, trans + SMPLX_PELVIS_OFFSET_M)  # (T, 3)
    root = pelvis * (CANONICAL_PELVIS_HEIGHT_M / SMPLX_PELVIS_HEIGHT_M)
    return HumanMotion(fps=fps, rotations=R.normalize(rot), root_pos_m=root, skeleton=CANONICAL)


#: Frame-wise arrays of a BEAT2 SMPL-X file besides ``poses`` and ``trans``, with their widths (filled with zeros).
_BEAT2_ZERO_FRAMES = {"expressions": 100}
_BEAT2_BETAS = 300


#: BEAT2's frame rate, which its FGD evaluator requires.
BEAT2_FPS = 30.0


def save_smplx(motion: HumanMotion, path: str | os.PathLike, fps: float = BEAT2_FPS) -> None:
    """Write ``motion`` (on :data:`CANONICAL`) as an SMPL-X parameter ``.npz`` in BEAT2's layout, atomically.

    The inverse of :func:`load_smplx`: the 14 upper-body joints' local rotations copy into their SMPL-X slots, the
    pelvis position becomes ``trans``; legs, jaw, eyes, fingers, ``betas`` and ``expressions`` are zero. This lets
    the BEAT2/EMAGE FGD evaluator (``robogest eval --fgd-weights``) score any generator's output.

    Keys: ``poses`` ``(T, 165)`` float32 axis-angle radians, ``trans`` ``(T, 3)`` metres, ``betas`` ``(300,)``,
    ``expressions`` ``(T, 100)``, ``mocap_frame_rate`` (int when whole), ``model`` ``"smplx2020"``, ``gender``
    ``"neutral"``. The motion is resampled to ``fps`` (BEAT2's 30 by default: the evaluator reads only that).
    """
    if motion.skeleton.names != CANONICAL.names:
        raise InputError(f"{path}: SMPL-X export needs motion on the canonical skeleton (map it first)")
    if abs(motion.fps - fps) > 1e-9:
        motion = motion.resample(fps)
    n = motion.n_frames
    poses = np.zeros((n, 55, 3))  # (T, 55 SMPL-X joints, axis-angle)
    for name, i in SMPLX_INDEX.items():
        poses[:, i] = R.to_axis_angle(motion.rotations[:, CANONICAL.index(name)])
    trans = motion.root_pos_m * (SMPLX_PELVIS_HEIGHT_M / CANONICAL_PELVIS_HEIGHT_M) - SMPLX_PELVIS_OFFSET_M  # (T, 3)
    fps = round(motion.fps) if abs(motion.fps - round(motion.fps)) < 1e-9 else float(motion.fps)
    arrays = {
        "poses": poses.reshape(n, 165).astype(np.float32),
        "trans": trans.astype(np.float64),
        "betas": np.zeros(_BEAT2_BETAS, np.float32),
        **{k: np.zeros((n, w)) for k, w in _BEAT2_ZERO_FRAMES.items()},
        "mocap_frame_rate": np.asarray(fps),
        "model": np.asarray("smplx2020"),
        "gender": np.asarray("neutral"),
    }
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)
