"""Human motion: skeletons, the canonical upper body, and BVH / SMPL-X import and export.

Every importer returns a :class:`HumanMotion` on :data:`CANONICAL` (Y up, facing +Z, +X = left, metres, T-pose rest)
so generators, metrics and retargeting see one skeleton whatever the dataset.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from robogest.errors import InputError
from robogest.motion.bvh import load_bvh, load_bvh_raw, save_bvh
from robogest.motion.human_motion import HumanMotion
from robogest.motion.mapping import NAME_MAPS, map_to_canonical
from robogest.motion.skeleton import CANONICAL, Skeleton
from robogest.motion.smplx import load_smplx, save_smplx

#: File suffix -> loader used by :func:`load_motion`, and writer used by :func:`save_motion`.
_LOADERS: dict[str, Callable[[Path], HumanMotion]] = {".bvh": load_bvh, ".npz": load_smplx}
_SAVERS: dict[str, Callable[[HumanMotion, Path], None]] = {".bvh": save_bvh, ".npz": save_smplx}


def load_motion(path: str | os.PathLike) -> HumanMotion:
    """Load a motion file onto :data:`CANONICAL`, choosing the reader by suffix (``.bvh``, ``.npz``)."""
    path = Path(path)
    loader = _LOADERS.get(path.suffix.lower())
    if loader is None:
        raise InputError(
            f"{path}: unsupported motion file type {path.suffix or '(none)'!r}; supported: {', '.join(_LOADERS)} "
            "(BVH motion capture, SMPL-X/AMASS .npz). Convert the file to one of these."
        )
    return loader(path)


def save_motion(motion: HumanMotion, path: str | os.PathLike) -> None:
    """Write ``motion`` choosing the format by suffix: ``.bvh`` (BVH), ``.npz`` (SMPL-X parameters, BEAT2 layout)."""
    path = Path(path)
    saver = _SAVERS.get(path.suffix.lower())
    if saver is None:
        raise InputError(
            f"{path}: cannot write motion as {path.suffix or '(no suffix)'!r}; name the file .bvh (BVH) or .npz "
            "(SMPL-X parameters in BEAT2's layout)"
        )
    saver(motion, path)


__all__ = [
    "CANONICAL",
    "NAME_MAPS",
    "HumanMotion",
    "Skeleton",
    "load_bvh",
    "load_bvh_raw",
    "load_motion",
    "load_smplx",
    "map_to_canonical",
    "save_bvh",
    "save_motion",
    "save_smplx",
]
