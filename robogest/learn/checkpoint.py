"""One ``.pt`` file per checkpoint: weights + model config + feature config + normalisation (+ training state).

Layout (a plain dict, loadable with ``torch.load(weights_only=True)``)::

    format            "robogest-checkpoint"
    version           1
    model_name        e.g. "gesticulator"
    model_config      dict of the model's config dataclass
    feature_config    FeatureConfig.to_dict()
    normalization     {name: float32 tensor}
    model_state       state_dict
    train_state       optional: optimizer state, next epoch, history, RNG state, train config

Writes are atomic (temporary file in the same folder, then ``os.replace``), so an interrupted run never leaves a
truncated checkpoint behind.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path
from robogest.learn import require_torch

FORMAT = "robogest-checkpoint"
VERSION = 1
#: Largest checkpoint file read, bytes (the shipped models are a few MB; a 1e9-parameter model is 4 GB).
MAX_CHECKPOINT_BYTES = 4 * 1024**3


def _tensors(d: dict[str, np.ndarray]) -> dict[str, Any]:
    torch = require_torch()
    return {k: torch.as_tensor(np.asarray(v, dtype=np.float32)) for k, v in d.items()}


def make_checkpoint(
    model_name: str,
    model_config: dict[str, Any],
    feature_config: dict[str, Any],
    normalization: dict[str, np.ndarray],
    model_state: dict[str, Any],
    train_state: dict[str, Any] | None = None,
) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "model_name": model_name,
        "model_config": dict(model_config),
        "feature_config": dict(feature_config),
        "normalization": _tensors(normalization),
        "model_state": model_state,
        "train_state": train_state,
    }


def save_checkpoint(ckpt: dict[str, Any], path: str | os.PathLike) -> Path:
    """Write ``ckpt`` to ``path`` atomically."""
    torch = require_torch()
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: a full disk raises OSError, not RuntimeError
        torch.save(ckpt, f)
    return path


def load_checkpoint(path: str | os.PathLike, map_location: str = "cpu") -> dict[str, Any]:
    """Read and check a checkpoint (``weights_only``: no code runs from the file).

    Raises
    ------
    InputError
        Missing, unreadable or not a robogest checkpoint.
    """
    torch = require_torch()
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: checkpoint not found (train one with `robogest train --model NAME ...`)")
    size = path.stat().st_size
    if size > MAX_CHECKPOINT_BYTES:
        raise InputError(
            f"{path}: {size / 1024**3:.1f} GiB is larger than the {MAX_CHECKPOINT_BYTES / 1024**3:.0f} GiB a "
            "robogest checkpoint can be"
        )
    # The zip format stores each tensor as a record whose length PyTorch checks against the declared size; the
    # legacy format allocates whatever the file declares before reading, so it is refused.
    if not zipfile.is_zipfile(path):
        raise InputError(f"{path}: not a readable checkpoint (not PyTorch's zip format: legacy or corrupt; re-save it)")
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as e:  # torch raises many types for corrupt files
        raise InputError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise InputError(f"{path}: not a robogest checkpoint (no format={FORMAT!r} field)")
    if ckpt.get("version", 0) > VERSION:
        raise InputError(f"{path}: checkpoint version {ckpt['version']} is newer than this robogest ({VERSION})")
    for key, kind in (("model_name", str), ("model_config", dict), ("feature_config", dict), ("normalization", dict)):
        if not isinstance(ckpt.get(key), kind):
            raise InputError(f"{path}: not a complete robogest checkpoint ({key!r} missing or not a {kind.__name__})")
    return ckpt


def build_model(ckpt: dict[str, Any], make: Callable[[], Any], path: str | os.PathLike, device: str = "cpu") -> Any:
    """The checkpoint's network with its weights loaded; its sizes are checked before any memory is allocated.

    ``make()`` builds the network from the checkpoint's config. It runs first on PyTorch's meta device (shapes
    only, no memory): a config that asks for other weights than the file stores (a crafted or corrupt file asking
    for gigabytes) is refused with one line, so the real network is never bigger than the file.
    """
    torch = require_torch()
    state = ckpt.get("model_state")
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: not a robogest checkpoint (model_state is not a dict of tensors)")
    try:
        with torch.device("meta"):
            want = {k: tuple(v.shape) for k, v in make().state_dict().items()}
    except (TypeError, ValueError, KeyError, RuntimeError) as e:
        raise InputError(f"{path}: invalid model config ({type(e).__name__}: {e})") from None
    have = {k: tuple(v.shape) for k, v in state.items()}
    if want != have:
        first = sorted(set(want.items()) ^ set(have.items()))[0]
        raise InputError(
            f"{path}: the stored weights do not match the model config (first difference: {first[0]} {first[1]}); "
            "the file is corrupt or was not written by this robogest"
        )
    model = make().to(torch.device(device))
    model.load_state_dict(state)
    return model


def normalization_arrays(ckpt: dict[str, Any]) -> dict[str, np.ndarray]:
    return {k: v.detach().cpu().numpy().astype(np.float32) for k, v in ckpt["normalization"].items()}
