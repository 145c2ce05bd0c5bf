"""FGD with the standard BEAT2/EMAGE evaluator network, comparable with the numbers EMAGE-era papers report.

FGD (Fréchet Gesture Distance) is the Fréchet distance between Gaussians fitted to the latent features of real
and generated motion. The features come from EMAGE's evaluator, a skeleton-aware convolutional auto-encoder
trained on BEAT2 (``AESKConv_240_100.bin``, published at :data:`WEIGHTS_URL`); its architecture is implemented in
:mod:`robogest.eval.fgd.network` and the user supplies the weights file. The protocol follows EMAGE's
``emage_evaltools``:

- input: SMPL-X axis-angle poses ``(T, 165)`` (all 55 joints, global orientation included, no translation) at
  30 fps, converted to rot6d (the first two rows of each rotation matrix) -> ``(T, 330)``;
- each take is cut to a multiple of 32 frames (the tail is dropped) and encoded whole (the network is fully
  convolutional), giving one 240-d latent frame per 16 input frames;
- latent frames of all takes are pooled per side and compared with the Fréchet distance.

Papers report FGD over a whole test set (e.g. the BEAT2 test split); a value from one short take is dominated by
sampling noise (about 120 latent frames for 240 dimensions per minute of motion) and compares only with itself.

Torch is imported only when an evaluator is loaded.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.eval.features import frechet_distance
from robogest.eval.fgd.topology import FPS, INPUT_DIM, N_JOINTS, TIME_DOWNSAMPLING, WINDOW

if TYPE_CHECKING:
    import torch

    from robogest.eval.fgd.network import MotionAutoencoder

#: File name of the published evaluator weights.
WEIGHTS_FILE = "AESKConv_240_100.bin"
#: Where EMAGE's authors publish it (Hugging Face model repository ``H-Liu1997/emage_evaltools``).
WEIGHTS_URL = "https://huggingface.co/H-Liu1997/emage_evaltools/resolve/main/AESKConv_240_100.bin"
#: SMPL-X axis-angle values per frame (55 joints x 3).
POSE_DIM = N_JOINTS * 3
_FIX = f"Download the BEAT2/EMAGE evaluator {WEIGHTS_FILE} from {WEIGHTS_URL} and pass its path."


def axis_angle_to_rot6d(poses: np.ndarray) -> np.ndarray:
    """SMPL-X axis-angle poses to the evaluator's rot6d input.

    Parameters
    ----------
    poses : ndarray [shape=(T, 165)], radians
        Axis-angle of the 55 SMPL-X joints in standard order.

    Returns
    -------
    ndarray [shape=(T, 330)]
        Per joint the first two rows of its rotation matrix (the layout EMAGE's ``matrix_to_rotation_6d`` uses).
    """
    from scipy.spatial.transform import Rotation

    t = poses.shape[0]
    mats: np.ndarray = Rotation.from_rotvec(
        np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    ).as_matrix()  # (T*55, 3, 3)
    rot6d: np.ndarray = mats[:, :2, :].reshape(t, N_JOINTS * 6)
    return rot6d


def check_poses(poses: np.ndarray, name: str = "poses", fps: float = FPS) -> np.ndarray:
    """``poses`` as float64 ``(T, 165)``, or an :class:`InputError` naming ``name`` and what to change."""
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != POSE_DIM:
        raise InputError(
            f"{name}: FGD needs SMPL-X axis-angle poses (T, {POSE_DIM}) (55 joints x 3), got shape {p.shape}"
        )
    if abs(fps - FPS) > 1e-6:
        raise InputError(f"{name}: FGD's evaluator was trained at {FPS:g} fps, got {fps:g} fps; resample to {FPS:g}")
    if p.shape[0] < WINDOW:
        raise InputError(f"{name}: FGD needs at least {WINDOW} frames ({WINDOW / FPS:.2f} s), got {p.shape[0]}")
    if not np.isfinite(p).all():
        raise InputError(f"{name}: poses contain NaN or infinite values")
    return p


class FGDEvaluator:
    """A loaded evaluator network; see :func:`load_evaluator`."""

    def __init__(self, model: MotionAutoencoder, device: str = "cpu") -> None:
        self.model = model
        self.device = device

    def features(self, poses: np.ndarray, name: str = "poses", fps: float = FPS) -> np.ndarray:
        """Latent features of one take.

        Parameters
        ----------
        poses : ndarray [shape=(T, 165)], radians
            SMPL-X axis-angle at 30 fps.
        name : str
            Named in errors.
        fps : float
            Frame rate of ``poses`` (must be 30).

        Returns
        -------
        ndarray [shape=(2 * (T // 32), 240)]
            One latent frame per 16 input frames; the last ``T % 32`` frames are dropped, as the reference does.
        """
        import torch

        p = check_poses(poses, name, fps)
        p = p[: p.shape[0] - p.shape[0] % WINDOW]
        x = torch.from_numpy(axis_angle_to_rot6d(p).astype(np.float32))[None].to(self.device)  # (1, T, 330)
        with torch.inference_mode():
            z = self.model.encode(x)[0]  # (T / 16, 240)
        return z.cpu().numpy().astype(np.float64)

    def fgd(self, real: np.ndarray | Sequence[np.ndarray], generated: np.ndarray | Sequence[np.ndarray]) -> float:
        """FGD between real and generated takes (each one array or a list of takes); see :func:`fgd`."""
        return frechet_distance(self._pooled(generated, "generated"), self._pooled(real, "real"))

    def _pooled(self, takes: np.ndarray | Sequence[np.ndarray], side: str) -> np.ndarray:
        if isinstance(takes, np.ndarray) and takes.ndim == 2:
            takes = [takes]
        pooled: np.ndarray = np.concatenate([self.features(t, f"{side} take {i}") for i, t in enumerate(takes)], axis=0)
        return pooled


def _describe(keys: Sequence[str], limit: int = 4) -> str:
    more = f" and {len(keys) - limit} more" if len(keys) > limit else ""
    return ", ".join(keys[:limit]) + more


def check_state_dict(
    state: Mapping[str, torch.Tensor], expected: Mapping[str, torch.Tensor], path: str | os.PathLike
) -> None:
    """Refuse a state dict that is not the evaluator's: missing or unexpected keys, other shapes, or skeleton
    masks/pooling matrices that differ from those derived from the SMPL-X tree. One :class:`InputError` lists
    what differs and says where to get the right file."""
    import torch

    problems = []
    missing = [k for k in expected if k not in state]
    unexpected = [k for k in state if k not in expected]
    if missing:
        problems.append(f"missing {len(missing)} keys ({_describe(missing)})")
    if unexpected:
        problems.append(f"{len(unexpected)} unexpected keys ({_describe(unexpected)})")
    shapes = [
        f"{k} {tuple(state[k].shape)} != {tuple(v.shape)}"
        for k, v in expected.items()
        if k in state and tuple(state[k].shape) != tuple(v.shape)
    ]
    if shapes:
        problems.append(f"{len(shapes)} tensors of another shape ({_describe(shapes)})")
    if not problems:
        fixed = [k for k in expected if k.endswith(".mask") or k.endswith("common.0.weight")]
        differ = [k for k in fixed if not torch.equal(state[k].to(expected[k].dtype), expected[k])]
        if differ:
            problems.append(f"skeleton masks/pooling differ from the SMPL-X tree ({_describe(differ)})")
    if problems:
        raise InputError(f"{path}: not the BEAT2/EMAGE FGD evaluator: {'; '.join(problems)}. {_FIX}")


def load_evaluator(path: str | os.PathLike, device: str = "cpu") -> FGDEvaluator:
    """Load ``AESKConv_240_100.bin`` (or a state dict of the same network), checking every key and shape.

    Parameters
    ----------
    path : path-like
        A torch file holding ``{"model_state": state_dict}`` (as published) or the state dict itself; DDP's
        ``module.`` prefixes are removed. Read with ``weights_only=True``: no code in the file is run.
    device : str
        Torch device for the encoder.

    Raises
    ------
    InputError
        The file is missing, unreadable, or not this network (names the file and where to download it).
    MissingDependencyError
        PyTorch is not installed.
    """
    from robogest.learn import require_torch

    torch = require_torch("FGD")
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such FGD weights file. {_FIX}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types (UnpicklingError, RuntimeError, EOFError, ...)
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        raise InputError(f"{path}: cannot read as torch weights ({type(e).__name__}: {first[:200]}). {_FIX}") from None
    state = ckpt.get("model_state", ckpt) if isinstance(ckpt, dict) else None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: holds no state dict of tensors (under 'model_state' or at the top). {_FIX}")
    state = {k.removeprefix("module."): v for k, v in state.items()}
    from robogest.eval.fgd.network import MotionAutoencoder

    model = MotionAutoencoder()
    check_state_dict(state, model.state_dict(), path)
    model.load_state_dict(state, strict=True)
    return FGDEvaluator(model.eval().to(device), device)


def fgd(
    real_poses: np.ndarray | Sequence[np.ndarray],
    gen_poses: np.ndarray | Sequence[np.ndarray],
    weights: str | os.PathLike | FGDEvaluator,
) -> float:
    """Fréchet Gesture Distance with the BEAT2/EMAGE evaluator.

    Parameters
    ----------
    real_poses, gen_poses : ndarray [shape=(T, 165)] or sequence of them, radians
        SMPL-X axis-angle poses at 30 fps; several takes per side are pooled (as over a test set).
    weights : path-like or FGDEvaluator
        ``AESKConv_240_100.bin`` (see :data:`WEIGHTS_URL`), or an evaluator already loaded.

    Returns
    -------
    float
        FGD in the evaluator's latent units (EMAGE's tables print it x 10⁻¹).
    """
    ev = weights if isinstance(weights, FGDEvaluator) else load_evaluator(weights)
    return ev.fgd(real_poses, gen_poses)


__all__ = [
    "FPS",
    "INPUT_DIM",
    "POSE_DIM",
    "TIME_DOWNSAMPLING",
    "WEIGHTS_FILE",
    "WEIGHTS_URL",
    "WINDOW",
    "FGDEvaluator",
    "axis_angle_to_rot6d",
    "check_poses",
    "check_state_dict",
    "fgd",
    "load_evaluator",
]
