"""Generic trainer: dataset folder in, checkpoints out; the model-specific parts come from a
:class:`~robogest.learn.spec.ModelSpec` (its hooks and their defaults are documented there).

Per epoch: shuffle the training windows with a generator seeded by ``(seed, epoch)`` (so a resumed run sees the
same order), one optimiser step per batch (or the spec's own :meth:`ModelSpec.train_step`, e.g. a GAN's
discriminator and generator steps), validation loss on the held-out takes, then ``last.pt`` (always) and
``best.pt`` (lowest validation loss) in the output folder, both complete enough to generate from. Under
``torchrun`` each rank trains on its shard of every batch through DistributedDataParallel and only rank 0 writes.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path, to_jsonable
from robogest.learn import dist as D
from robogest.learn import require_torch
from robogest.learn.checkpoint import make_checkpoint, save_checkpoint
from robogest.learn.setup import TrainingRun, setup_run
from robogest.learn.spec import ModelSpec

if TYPE_CHECKING:
    from rich.progress import Progress

__all__ = ["EpochLog", "ModelSpec", "TrainConfig", "train"]


@dataclass
class TrainConfig:
    """One training run (defaults follow the paper of the model: Gesticulator §4.3-4.4).

    Attributes
    ----------
    model : str
        Registered model name.
    data, out : str
        Dataset folder; output folder for ``last.pt``, ``best.pt`` and ``history.json``.
    epochs : int
        Total epochs (a resumed run continues up to this number).
    batch_size : int
        Global batch (split over DDP ranks).
    lr : float or None
        Adam learning rate; None: the model config's ``lr`` (its paper's value) or 1e-4.
    seed : int
        Seeds the split, initialisation, shuffling and dropout.
    device : {"auto", "cpu", "cuda"}
    resume : bool
        Continue from ``out/last.pt`` when it exists.
    val_fraction : float
        Share of takes held out for validation.
    window_stride : int
        Frames between the starts of consecutive training windows.
    text_encoder : str
        Registered text encoder; ``text_encoder_kwargs`` its arguments.
    cache_dir : str or None
        Feature cache (default :func:`robogest.data.default_cache_dir`); models that cut takes their own way keep
        those cuts there too (the rhythmic model's time-scaled blocks).
    dist_timeout_s : float
        Under ``torchrun``: how long a rank waits for the others at a collective (e.g. while rank 0 builds caches).
    model_overrides : dict
        Fields of the model config to change (e.g. ``{"pretrain_epochs": 2}``).
    """

    model: str = "gesticulator"
    data: str = ""
    out: str = ""
    epochs: int = 20
    batch_size: int = 64
    lr: float | None = None
    seed: int = 0
    device: str = "auto"
    resume: bool = False
    val_fraction: float = 0.1
    window_stride: int = 5
    text_encoder: str = "minilm"
    text_encoder_kwargs: dict[str, Any] = field(default_factory=dict)
    cache_dir: str | None = None
    dist_timeout_s: float = D.DEFAULT_TIMEOUT_S
    model_overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class EpochLog:
    epoch: int
    train_loss: float
    val_loss: float
    seconds: float
    parts: dict[str, float] = field(default_factory=dict)  # train_step's named values, epoch means


def _progress(enabled: bool) -> Progress | None:
    """A rich bar over batches on a terminal; a no-op otherwise (logs still print per epoch)."""
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
        TextColumn("loss {task.fields[loss]}"), TimeRemainingColumn(), transient=True,
    )  # fmt: skip


def _batches(n: int, batch: int, generator: Any, info: D.DistInfo) -> list[np.ndarray]:
    """Shuffled index batches of the global size (``generator``: a seeded ``torch.Generator``); each rank keeps its
    strided share of every batch.

    A last batch with fewer windows than ranks is dropped on every rank: every rank must take the same number of
    steps, or the next collective (DDP's gradient all-reduce) waits for a rank that has none and the job aborts.
    """
    torch = require_torch()
    perm = torch.randperm(n, generator=generator).numpy()
    return [
        perm[s : s + batch][info.rank :: info.world_size]
        for s in range(0, n, batch)
        if perm[s : s + batch].size >= info.world_size
    ]


def train(cfg: TrainConfig, spec: ModelSpec[Any], log: Callable[[str], None] | None = None) -> Path:
    """Run training of the model ``spec`` describes (``robogest.generators.learned.get_model_spec(cfg.model)``);
    returns the path of the best checkpoint.

    Raises
    ------
    InputError
        ``spec`` is not ``cfg.model``'s, bad folder, too little data for one window, a resume checkpoint of another
        model or feature setup.
    """
    require_torch()  # before anything else: a missing torch names the extra to install
    if spec.name != cfg.model:
        raise InputError(f"TrainConfig names model {cfg.model!r} but the spec is {spec.name!r}'s")
    info, device = D.setup(cfg.device, cfg.dist_timeout_s)
    say = (log or (lambda s: print(s, flush=True))) if info.is_main else (lambda s: None)
    try:
        result = _train(cfg, spec, info, device, say)
        # The model, its DistributedDataParallel wrapper (whose reducer holds the process group) and the gradient
        # hooks are freed now, while the interpreter is whole: gloo work objects left for interpreter shutdown
        # can abort the process (pytorch/pytorch#179291). A mitigation, not a proven cure: a rank 1 SIGABRT after
        # training was seen twice in the suite on a 2-core machine, but not in 12 runs of the DDP test under load.
        gc.collect()
        # Every rank done with its collectives before any takes the group down: a rank that destroyed it and
        # exited while rank 0 was still writing its last checkpoint once died of SIGABRT in gloo's threads
        # ("terminate called without an active exception", CI-class machine under load).
        D.barrier(info)
        return result
    finally:
        D.teardown(info)


def _train(cfg: TrainConfig, spec: ModelSpec[Any], info: D.DistInfo, device: Any, say: Callable[[str], None]) -> Path:
    """Set up, then per epoch: train, validate, record, save."""
    run = setup_run(cfg, spec, info, device, say)
    bar = _progress(info.is_main)
    for epoch in range(run.start, cfg.epochs):
        stage = spec.stage_name(epoch, run.mcfg)
        what = f"epoch {epoch + 1}/{cfg.epochs}" + (f" [{stage}]" if stage else "")
        t_ep = time.perf_counter()
        train_loss, parts = _train_epoch(run, epoch, bar, what)
        val = _evaluate(run, epoch)
        improved = _record(run, epoch, stage, train_loss, val, parts, t_ep)
        if info.is_main:
            _save(run, epoch, stage, improved)
        say(
            f"{what}  train {train_loss:.4f}  val {val:.4f}  "
            f"{run.history[-1]['seconds']:.1f} s{'  *best' if improved else ''}"
        )
    if bar:
        bar.stop()
    return run.out / "best.pt"


# -- epoch, validation, saving ------------------------------------------------------------------------------------


def _train_epoch(run: TrainingRun, epoch: int, bar: Progress | None, what: str) -> tuple[float, dict[str, float]]:
    """One pass over this rank's share of the shuffled windows; the train loss and the step's named values, both
    averaged over windows and ranks (``parts`` empty for a spec without its own step)."""
    torch = require_torch()
    cfg, spec, device = run.cfg, run.spec, run.device
    g = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
    batches = _batches(len(run.xs), cfg.batch_size, g, run.info)
    run.net.train()
    total, count = 0.0, 0
    parts: dict[str, float] = {}
    task = bar.add_task(what, total=len(batches), loss="-") if bar else None
    if bar and epoch == run.start:
        bar.start()
    sync = D.sync_of(run.info)
    for b in batches:
        xb, yb = torch.from_numpy(run.xs[b]).to(device), torch.from_numpy(run.ys[b]).to(device)  # read from disk
        with torch.no_grad():
            spec.before_step(run.model, xb, yb, epoch, run.mcfg, sync)
        stats = spec.train_step(run.net, run.optimizers, xb, yb, epoch, run.mcfg)
        if spec.custom_step:
            for k, v in stats.items():
                parts[k] = parts.get(k, 0.0) + float(v) * len(b)
        total += float(stats["loss"]) * len(b)
        count += len(b)
        if bar and task is not None:
            bar.update(task, advance=1, loss=f"{total / count:.4f}")
    if bar and task is not None:
        bar.remove_task(task)
    train_loss = D.all_reduce_mean([total / max(count, 1)], run.info, device)[0]
    means = D.all_reduce_mean([v / max(count, 1) for v in parts.values()], run.info, device)
    return train_loss, dict(zip(parts, means, strict=True))


def _evaluate(run: TrainingRun, epoch: int) -> float:
    """Mean validation loss over the held-out windows (every rank evaluates all; NaN without validation windows)."""
    vx, vy = run.vx, run.vy
    if vx.shape[0] == 0:
        return math.nan
    torch = require_torch()
    run.model.eval()
    total, batch = 0.0, run.cfg.batch_size
    with torch.no_grad():
        for s in range(0, vx.shape[0], batch):
            xb = torch.from_numpy(vx[s : s + batch]).to(run.device)
            yb = torch.from_numpy(vy[s : s + batch]).to(run.device)
            total += float(run.spec.validation_loss(run.model, xb, yb, epoch, run.mcfg)) * xb.shape[0]
    return total / int(vx.shape[0])


def _record(
    run: TrainingRun, epoch: int, stage: str, train_loss: float, val: float, parts: dict[str, float], t_ep: float
) -> bool:
    """Append the epoch to the history; True when its score (validation loss, else train loss) is the best yet
    among the epochs that may become ``best.pt``."""
    entry = dataclasses.asdict(EpochLog(epoch + 1, train_loss, val, time.perf_counter() - t_ep, parts))
    if not entry["parts"]:
        del entry["parts"]  # plain specs keep their history format
    if stage:
        entry["stage"] = stage
    run.history.append(entry)
    score = val if not math.isnan(val) else train_loss
    improved = epoch >= run.first_best and score < run.best
    run.best = score if improved else run.best
    return improved


def _save(run: TrainingRun, epoch: int, stage: str, improved: bool) -> None:
    """``last.pt`` always, ``best.pt`` when ``improved`` (or missing once warm-up is over), ``history.json``."""
    ckpt = _checkpoint(run, epoch + 1, stage)
    save_checkpoint(ckpt, run.out / "last.pt")
    best_path = run.out / "best.pt"
    if epoch >= run.first_best and (improved or not best_path.is_file()):  # never a warm-up stage's model
        save_checkpoint(ckpt, best_path)
    with atomic_path(run.out / "history.json") as tmp:
        tmp.write_text(json.dumps(to_jsonable(run.history), indent=1, allow_nan=False), encoding="utf-8")


def _checkpoint(run: TrainingRun, next_epoch: int, stage: str) -> dict[str, Any]:
    """A checkpoint complete enough to generate from and to resume at ``next_epoch``."""
    torch = require_torch()
    opt_states = {name: o.state_dict() for name, o in run.optimizers.items()}
    train_state = {
        # one optimiser keeps the original "optimizer" key, so older readers still resume
        **({"optimizer": opt_states["optimizer"]} if list(opt_states) == ["optimizer"] else {}),
        "optimizers": opt_states,
        "next_epoch": next_epoch,
        "stage": stage,  # the phase the weights come from (e.g. Gesticulator's pre-training vs autoregressive)
        "history": run.history,
        "best_val": run.best,
        "rng_cpu": torch.get_rng_state(),
        "rng_cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
        "train_config": json.loads(json.dumps(dataclasses.asdict(run.cfg), default=str)),
    }
    state = {k: v.detach().cpu() for k, v in run.model.state_dict().items()}
    return make_checkpoint(
        run.cfg.model, dataclasses.asdict(run.mcfg), run.fcfg.to_dict(), run.norm.to_dict(), state, train_state
    )
