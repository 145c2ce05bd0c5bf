"""The set-up half of a training run (:func:`robogest.learn.trainer.train`): options checked, takes loaded, model
config made (fresh) or restored (``--resume``), windows cut, model and optimisers built and wrapped for DDP.

Everything a spec decides comes through :class:`robogest.learn.spec.ModelSpec`'s methods.
"""

from __future__ import annotations

import math
import os
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.data.datasets import Take, load_dataset, official_split
from robogest.data.features import FeatureConfig
from robogest.data.prep import Normalization, split_takes
from robogest.errors import InputError
from robogest.learn import dist as D
from robogest.learn import require_torch
from robogest.learn.checkpoint import load_checkpoint
from robogest.learn.spec import ModelSpec

if TYPE_CHECKING:
    from robogest.learn.trainer import TrainConfig


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy and torch, and make torch's kernels deterministic (warn where one is not)."""
    torch = require_torch()
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True, warn_only=True)


@dataclass
class TrainingRun:
    """One training run's state between epochs (what :func:`setup_run` builds and the epoch loop updates)."""

    cfg: TrainConfig
    spec: ModelSpec[Any]
    info: D.DistInfo
    device: Any  # torch.device
    say: Callable[[str], None]
    fcfg: FeatureConfig
    mcfg: Any  # the spec's model config
    norm: Normalization
    model: Any  # torch.nn.Module
    net: Any  # what batches go through: model, or its DistributedDataParallel wrapper
    optimizers: dict[str, Any]
    xs: Any  # training windows (N, L, F), (N, L, P)
    ys: Any
    vx: Any  # validation windows (M, L_val, F), (M, L_val, P)
    vy: Any
    first_best: int
    start: int = 0
    history: list[dict[str, Any]] = field(default_factory=list)
    best: float = math.inf

    @property
    def out(self) -> Path:
        return Path(self.cfg.out)


def setup_run(
    cfg: TrainConfig, spec: ModelSpec[Any], info: D.DistInfo, device: Any, say: Callable[[str], None]
) -> TrainingRun:
    """Check the run's options, load the takes, make or restore the model config, cut the windows, build the model
    and its optimisers (restored on ``--resume``) and wrap it for DDP."""
    _check_options(cfg, info)
    seed_everything(cfg.seed)
    fcfg = FeatureConfig(text_encoder=cfg.text_encoder, text_encoder_kwargs=dict(cfg.text_encoder_kwargs))
    t0 = time.perf_counter()
    takes = D.builder_first(
        info,
        lambda: load_dataset(cfg.data, fcfg, cfg.cache_dir),
        lambda: load_dataset(cfg.data, fcfg, cfg.cache_dir, warn=lambda s: None, build=False),
    )  # memory-mapped from the cache: one copy in the page cache whatever the number of ranks
    minutes = sum(t.n_frames for t in takes) / fcfg.fps / 60
    say(f"{len(takes)} takes, {minutes:.1f} min of speech (features in {time.perf_counter() - t0:.1f} s)")
    train_takes, val_takes = split_takes(takes, cfg.val_fraction, cfg.seed, official_split(cfg.data))
    norm = Normalization.fit(train_takes)
    sizes = (takes[0].acoustic.shape[1], takes[0].text.shape[1], takes[0].poses.shape[1])  # acoustic, text, pose

    out = Path(cfg.out)
    resume_ckpt = _resume_checkpoint(cfg, fcfg) if cfg.resume and (out / "last.pt").is_file() else None
    if resume_ckpt is not None:
        mcfg = _resumed_config(cfg, spec, resume_ckpt, sizes)
        norm = Normalization.from_dict({k: v.numpy() for k, v in resume_ckpt["normalization"].items()})
    else:
        mcfg = spec.make_config(*sizes, dict(cfg.model_overrides))
        mcfg = spec.plan_epochs(spec.fit_config(mcfg, train_takes), cfg.epochs)
    first_best = spec.first_best_epoch(mcfg)
    if cfg.epochs <= first_best:
        raise InputError(
            f"{spec.name}: --epochs {cfg.epochs} ends before any epoch may become best.pt (the first is epoch "
            f"{first_best + 1}, after {spec.stage_name(0, mcfg) or 'warm-up'}); train at least {first_best + 1} epochs"
        )
    seq, v_len = spec.sequence_length(mcfg), spec.validation_length(mcfg)
    xs, ys, vx, vy = _windows(spec, mcfg, train_takes, val_takes, norm, seq, cfg, v_len, info)
    if xs.shape[0] == 0:
        raise InputError(f"{cfg.data}: no training take is {seq} frames ({seq / fcfg.fps:.1f} s) long")
    say(f"{xs.shape[0]} training windows of {seq} frames, {vx.shape[0]} validation of {v_len}; device {device}")
    if val_takes and vx.shape[0] == 0:
        say(f"no validation take is {v_len} frames ({v_len / fcfg.fps:.1f} s) long: best.pt follows the train loss")

    model = spec.build(mcfg).to(device)
    optimizers = dict(spec.make_optimizers(model, cfg, mcfg))
    run = TrainingRun(
        cfg, spec, info, device, say, fcfg, mcfg, norm, model, model, optimizers, xs, ys, vx, vy, first_best
    )
    if resume_ckpt is not None:
        _restore(run, resume_ckpt)
    run.net = _wrap_for_ddp(model, spec, info, device)
    return run


def _check_options(cfg: TrainConfig, info: D.DistInfo) -> None:
    if cfg.epochs < 1 or cfg.batch_size < 1 or (cfg.lr is not None and not cfg.lr > 0):
        raise InputError("epochs and batch size must be >= 1 and lr > 0")
    if cfg.batch_size < info.world_size:
        raise InputError(
            f"--batch-size {cfg.batch_size} is smaller than the {info.world_size} processes: each needs a window "
            "per step; use a batch size of at least the number of processes"
        )
    out = Path(cfg.out)
    if not cfg.resume and (out / "last.pt").is_file():
        raise InputError(
            f"{out} already holds a training run (last.pt): pass --resume to continue it, or choose a new --out "
            "(nothing was overwritten)"
        )


def _resume_checkpoint(cfg: TrainConfig, fcfg: FeatureConfig) -> dict[str, Any]:
    """``out/last.pt``, checked to be this model's and feature set-up's, with training state and the same lr."""
    path = Path(cfg.out) / "last.pt"
    ckpt = load_checkpoint(path, map_location="cpu")
    if ckpt["model_name"] != cfg.model or ckpt["feature_config"] != fcfg.to_dict():
        raise InputError(f"{path}: written for another model or feature set-up; use a new --out")
    ts = ckpt.get("train_state")
    if not isinstance(ts, dict) or not {"next_epoch", "history", "best_val", "rng_cpu"} <= set(ts):
        raise InputError(f"{path}: holds no training state to resume from; use a new --out")
    was = (ts.get("train_config") or {}).get("lr")
    if cfg.lr is not None and was is not None and float(was) != cfg.lr:
        raise InputError(
            f"--resume continues {path}, trained with --lr {was}; --lr {cfg.lr} would not apply to its optimiser "
            "state: drop --lr, or train into a new --out"
        )
    return ckpt


def _resumed_config(cfg: TrainConfig, spec: ModelSpec[Any], ckpt: dict[str, Any], sizes: tuple[int, int, int]) -> Any:
    """The model config saved in ``ckpt``; ``--set`` options that would change it are refused."""
    mcfg = spec.config_from_dict(ckpt["model_config"])
    wanted = spec.make_config(*sizes, dict(cfg.model_overrides))  # refuses unknown keys
    changed = sorted(k for k in dict(cfg.model_overrides) if getattr(wanted, k) != getattr(mcfg, k))
    if changed:
        was = ", ".join(f"{k}={getattr(mcfg, k)!r}" for k in changed)
        raise InputError(
            f"--resume continues {Path(cfg.out) / 'last.pt'}, trained with {was}; --set cannot change a model being "
            "resumed: drop those --set options, or train into a new --out"
        )
    return mcfg


def _restore(run: TrainingRun, ckpt: dict[str, Any]) -> None:
    """Weights, optimisers, history, best score and RNG state of a resumed run."""
    torch = require_torch()
    run.model.load_state_dict(ckpt["model_state"])
    ts = ckpt["train_state"]
    saved = ts["optimizers"] if "optimizers" in ts else {"optimizer": ts["optimizer"]}
    if set(saved) != set(run.optimizers):
        raise InputError(
            f"{run.out / 'last.pt'}: optimisers {sorted(saved)} do not match {sorted(run.optimizers)}; use a new --out"
        )
    for name, o in run.optimizers.items():
        o.load_state_dict(saved[name])
    run.start, run.history, run.best = int(ts["next_epoch"]), list(ts["history"]), float(ts["best_val"])
    torch.set_rng_state(ts["rng_cpu"])
    if ts.get("rng_cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(ts["rng_cuda"])  # dropout masks on the GPU continue as uninterrupted
    run.say(f"resumed from {run.out / 'last.pt'} at epoch {run.start}")


def _wrap_for_ddp(model: Any, spec: ModelSpec[Any], info: D.DistInfo, device: Any) -> Any:
    """What batches go through under torchrun: gradient-averaging hooks for a spec with its own step, else a
    DistributedDataParallel wrapper; the model itself when alone."""
    if not info.enabled:
        return model
    if spec.custom_step:
        if info.world_size > 1:
            _average_gradients_hooks(model, info)
        return model
    from torch.nn.parallel import DistributedDataParallel as DDP

    # Pre-training epochs leave the autoregressive pose encoder unused, hence find_unused_parameters.
    return DDP(model, device_ids=[device.index] if device.type == "cuda" else None, find_unused_parameters=True)


def _windows(
    spec: ModelSpec[Any], mcfg: Any, train_takes: Sequence[Take], val_takes: Sequence[Take], norm: Normalization,
    seq: int, cfg: TrainConfig, v_len: int, info: D.DistInfo,
) -> tuple[Any, Any, Any, Any]:  # fmt: skip
    """Training ``(N, seq, ·)`` and validation ``(M, v_len, ·)`` windows, memory-mapped from files that each node's
    first rank writes under ``out`` and the other ranks map (:func:`robogest.learn.dist.builder_first`); the files
    are unlinked once every rank has mapped them, so they vanish with the run (as anonymous temporary files do).
    """
    import shutil
    import socket

    from robogest.data.datasets import default_cache_dir

    stride, out = cfg.window_stride, Path(cfg.out)
    store = out / f".windows-{socket.gethostname()}-{os.getpid() if not info.enabled else 'ddp'}"
    cache_dir = Path(cfg.cache_dir) if cfg.cache_dir else default_cache_dir()

    def cut(takes: Sequence[Take], length: int, step: int, name: str) -> tuple[Any, Any]:
        x, y, _ = spec.make_windows(takes, norm, mcfg, length, step, store=store / name, cache_dir=cache_dir)
        return x, y

    def read() -> tuple[Any, Any, Any, Any]:  # writes the windows where they are missing
        return (*cut(train_takes, seq, stride, "train"), *cut(val_takes, v_len, v_len // 2, "val"))

    def build() -> tuple[Any, Any, Any, Any]:
        shutil.rmtree(store, ignore_errors=True)  # a crashed run's leftovers
        return read()

    if info.world_size > 1:  # every rank fills the cache for its share of the takes
        spec.warm_cache([*train_takes, *val_takes], mcfg, cache_dir, info.rank, info.world_size)
        D.barrier(info)
    arrays: tuple[Any, Any, Any, Any] = D.builder_first(info, build, read)
    D.barrier(info)  # every rank has mapped them
    if info.local_rank == 0:
        shutil.rmtree(store, ignore_errors=True)
    return arrays


def _average_gradients_hooks(model: Any, info: D.DistInfo) -> None:
    """Make every gradient the mean over ranks as it is computed (DDP's job, for specs with their own step).

    A spec with :meth:`train_step` calls parts of the model (generator, discriminator) directly, which bypasses a
    DistributedDataParallel wrapper's synchronisation; every rank runs the same sequence of backward passes, so
    per-parameter all-reduce hooks keep the replicas identical (they start identical: same seed).
    """
    import torch.distributed as dist

    def hook(g: Any) -> Any:
        g = g.clone()
        dist.all_reduce(g)
        return g / info.world_size

    for p in model.parameters():
        if p.requires_grad:
            p.register_hook(hook)
