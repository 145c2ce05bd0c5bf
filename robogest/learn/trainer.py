"""Generic trainer: dataset folder in, checkpoints out; the model-specific parts come from a :class:`ModelSpec`.

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
import os
import random
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from robogest.data.datasets import load_dataset, official_split
from robogest.data.features import FeatureConfig
from robogest.data.prep import Normalization, make_windows, split_takes
from robogest.errors import InputError
from robogest.fileio import atomic_path, to_jsonable
from robogest.learn import dist as D
from robogest.learn import require_torch
from robogest.learn.checkpoint import load_checkpoint, make_checkpoint, save_checkpoint


class ModelSpec(Protocol):
    """What the trainer needs from a model family."""

    name: str

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> Any:
        """The model's config dataclass for these input/output sizes."""

    def config_from_dict(self, d: dict[str, Any]) -> Any: ...

    def build(self, config: Any) -> Any:
        """A ``torch.nn.Module``."""

    def sequence_length(self, config: Any) -> int:
        """Frames per training window."""

    def loss(self, model: Any, speech: Any, poses: Any, epoch: int, config: Any) -> Any:
        """Scalar loss of one batch ``(B, L, F)``, ``(B, L, P)`` at ``epoch`` (0-based); also the validation loss."""


#: Optional :class:`ModelSpec` methods, looked up with ``getattr`` so specs without them keep the plain path:
#:
#: ``fit_config(config, train_takes) -> config``
#:     Fill data-dependent config fields (speaker table, feature statistics) from the training takes; called once
#:     on a fresh run (a resumed run restores the config from the checkpoint).
#: ``make_windows(takes, norm, config, length, stride, store=None) -> (x, y, take_index)``
#:     The spec's own training arrays ``(N, L, F)``, ``(N, L, P)``, ``(N,)`` instead of
#:     :func:`robogest.data.prep.make_windows` (other inputs or targets than normalised mel+text / exp-maps);
#:     ``store`` goes to :func:`robogest.data.prep.slice_windows`, so DDP ranks map one copy.
#: ``make_optimizers(model, train_config, config) -> dict[str, Optimizer]``
#:     Several optimisers (e.g. generator and discriminator); all are saved in and restored from checkpoints.
#: ``train_step(model, optimizers, speech, poses, epoch, config) -> dict[str, float]``
#:     One batch, including ``zero_grad``/``backward``/``step``; must return ``"loss"`` (the value logged as the
#:     train loss) and may return more named values, averaged per epoch into ``history.json``.
#: ``plan_epochs(config, epochs) -> config``
#:     Fill epoch-dependent config fields (a schedule of training stages) from ``--epochs``; fresh runs only, so a
#:     resumed run keeps the plan in its checkpoint.
#: ``validation_loss(model, speech, poses, epoch, config) -> Tensor``
#:     The held-out loss ``best.pt`` is chosen on, instead of :meth:`ModelSpec.loss`: an autoregressive model's
#:     free-running rollout (its own outputs fed back, as at run time), not a teacher-forced one.
#: ``validation_length(config) -> int``
#:     Frames per held-out sequence (default :meth:`ModelSpec.sequence_length`), e.g. several chained windows for
#:     a rollout that feeds its own outputs across windows.
#: ``first_best_epoch(config) -> int``
#:     Epochs before this one (0-based) never become ``best.pt`` (e.g. before every stage has trained).
#: ``stage_name(epoch, config) -> str``
#:     What the epoch trains, for the log line and ``history.json``.
#: ``before_step(model, speech, poses, epoch, config, sync) -> None``
#:     Update state that is not learned by gradient (e.g. a codebook's dead-code restarts) from this rank's batch,
#:     before its step, under ``no_grad``; ``sync`` (:func:`robogest.learn.dist.sync_of`, None alone) makes the
#:     change the same on every rank. Called on every rank for every batch, so its collectives always match.
#: ``make_windows`` may also take ``cache_dir``: the run's cache folder, for window parts worth keeping across runs.
#: ``warm_cache(takes, config, cache_dir, rank, world_size) -> None``
#:     Under torchrun, before the windows are cut on each node's first rank: fill ``cache_dir`` for this rank's
#:     share of ``takes``, so the slow per-take work is spread over all ranks instead of done by one.
OPTIONAL_SPEC_METHODS = (
    "fit_config", "make_windows", "make_optimizers", "train_step", "plan_epochs", "validation_loss",
    "validation_length", "first_best_epoch", "stage_name", "before_step", "warm_cache",
)  # fmt: skip


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


def _average_gradients_hooks(model, info: D.DistInfo) -> None:
    """Make every gradient the mean over ranks as it is computed (DDP's job, for specs with their own step).

    A spec with :meth:`train_step` calls parts of the model (generator, discriminator) directly, which bypasses a
    DistributedDataParallel wrapper's synchronisation; every rank runs the same sequence of backward passes, so
    per-parameter all-reduce hooks keep the replicas identical (they start identical: same seed).
    """
    import torch.distributed as dist

    def hook(g):
        g = g.clone()
        dist.all_reduce(g)
        return g / info.world_size

    for p in model.parameters():
        if p.requires_grad:
            p.register_hook(hook)


def seed_everything(seed: int) -> None:
    torch = require_torch()
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True, warn_only=True)


def _progress(enabled: bool):
    """A rich bar over batches on a terminal; a no-op otherwise (logs still print per epoch)."""
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
        TextColumn("loss {task.fields[loss]}"), TimeRemainingColumn(), transient=True,
    )  # fmt: skip


def _batches(n: int, batch: int, generator, info: D.DistInfo) -> list[np.ndarray]:
    """Shuffled index batches of the global size; each rank keeps its strided share of every batch.

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


def train(cfg: TrainConfig, spec: ModelSpec, log: Callable[[str], None] | None = None) -> Path:
    """Run training of the model ``spec`` describes (``robogest.generators.learned.get_model_spec(cfg.model)``);
    returns the path of the best checkpoint.

    Raises
    ------
    InputError
        ``spec`` is not ``cfg.model``'s, bad folder, too little data for one window, a resume checkpoint of another
        model or feature setup.
    """
    torch = require_torch()
    if spec.name != cfg.model:
        raise InputError(f"TrainConfig names model {cfg.model!r} but the spec is {spec.name!r}'s")
    info, device = D.setup(cfg.device, cfg.dist_timeout_s)
    say = (log or (lambda s: print(s, flush=True))) if info.is_main else (lambda s: None)
    try:
        result = _train(cfg, spec, info, device, say, torch)
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


def _train(cfg: TrainConfig, spec: ModelSpec, info: D.DistInfo, device, say, torch) -> Path:
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
    n_acoustic, n_text, n_pose = takes[0].acoustic.shape[1], takes[0].text.shape[1], takes[0].poses.shape[1]

    resume_ckpt = None
    if cfg.resume and (out / "last.pt").is_file():
        resume_ckpt = load_checkpoint(out / "last.pt", map_location="cpu")
        if resume_ckpt["model_name"] != cfg.model or resume_ckpt["feature_config"] != fcfg.to_dict():
            raise InputError(f"{out / 'last.pt'}: written for another model or feature set-up; use a new --out")
        ts = resume_ckpt.get("train_state")
        if not isinstance(ts, dict) or not {"next_epoch", "history", "best_val", "rng_cpu"} <= set(ts):
            raise InputError(f"{out / 'last.pt'}: holds no training state to resume from; use a new --out")
        was = (ts.get("train_config") or {}).get("lr")
        if cfg.lr is not None and was is not None and float(was) != cfg.lr:
            raise InputError(
                f"--resume continues {out / 'last.pt'}, trained with --lr {was}; --lr {cfg.lr} would not apply to "
                "its optimiser state: drop --lr, or train into a new --out"
            )
        mcfg = spec.config_from_dict(resume_ckpt["model_config"])
        wanted = spec.make_config(n_acoustic, n_text, n_pose, dict(cfg.model_overrides))  # refuses unknown keys
        changed = sorted(k for k in dict(cfg.model_overrides) if getattr(wanted, k) != getattr(mcfg, k))
        if changed:
            was = ", ".join(f"{k}={getattr(mcfg, k)!r}" for k in changed)
            raise InputError(
                f"--resume continues {out / 'last.pt'}, trained with {was}; --set cannot change a model being "
                "resumed: drop those --set options, or train into a new --out"
            )
        norm = Normalization.from_dict({k: v.numpy() for k, v in resume_ckpt["normalization"].items()})
    else:
        mcfg = spec.make_config(n_acoustic, n_text, n_pose, dict(cfg.model_overrides))
        if hasattr(spec, "fit_config"):
            mcfg = spec.fit_config(mcfg, train_takes)
        if hasattr(spec, "plan_epochs"):
            mcfg = spec.plan_epochs(mcfg, cfg.epochs)
    first_best = spec.first_best_epoch(mcfg) if hasattr(spec, "first_best_epoch") else 0
    if cfg.epochs <= first_best:
        raise InputError(
            f"{spec.name}: --epochs {cfg.epochs} ends before any epoch may become best.pt (the first is epoch "
            f"{first_best + 1}, after {spec.stage_name(0, mcfg) if hasattr(spec, 'stage_name') else 'warm-up'}); "
            f"train at least {first_best + 1} epochs"
        )
    seq = spec.sequence_length(mcfg)
    v_len = spec.validation_length(mcfg) if hasattr(spec, "validation_length") else seq
    xs, ys, vx, vy = _windows(spec, mcfg, train_takes, val_takes, norm, seq, cfg, v_len, info)
    if xs.shape[0] == 0:
        raise InputError(f"{cfg.data}: no training take is {seq} frames ({seq / fcfg.fps:.1f} s) long")
    say(f"{xs.shape[0]} training windows of {seq} frames, {vx.shape[0]} validation of {v_len}; device {device}")
    if val_takes and vx.shape[0] == 0:
        say(f"no validation take is {v_len} frames ({v_len / fcfg.fps:.1f} s) long: best.pt follows the train loss")

    model = spec.build(mcfg).to(device)
    custom_step = hasattr(spec, "train_step")
    if hasattr(spec, "make_optimizers"):
        optimizers = dict(spec.make_optimizers(model, cfg, mcfg))
    else:
        lr = cfg.lr if cfg.lr is not None else float(getattr(mcfg, "lr", 1e-4))
        optimizers = {"optimizer": torch.optim.Adam(model.parameters(), lr=lr)}
    start, history, best = 0, [], math.inf
    if resume_ckpt is not None:
        model.load_state_dict(resume_ckpt["model_state"])
        ts = resume_ckpt["train_state"]
        saved = ts["optimizers"] if "optimizers" in ts else {"optimizer": ts["optimizer"]}
        if set(saved) != set(optimizers):
            raise InputError(f"{out / 'last.pt'}: optimisers {sorted(saved)} do not match {sorted(optimizers)}")
        for name, o in optimizers.items():
            o.load_state_dict(saved[name])
        start, history, best = int(ts["next_epoch"]), list(ts["history"]), float(ts["best_val"])
        torch.set_rng_state(ts["rng_cpu"])
        if ts.get("rng_cuda") is not None and torch.cuda.is_available():
            torch.cuda.set_rng_state_all(ts["rng_cuda"])  # dropout masks on the GPU continue as uninterrupted
        say(f"resumed from {out / 'last.pt'} at epoch {start}")
    net = model
    if info.enabled and custom_step:
        if info.world_size > 1:
            _average_gradients_hooks(model, info)
    elif info.enabled:
        from torch.nn.parallel import DistributedDataParallel as DDP

        # Pre-training epochs leave the autoregressive pose encoder unused, hence find_unused_parameters.
        net = DDP(model, device_ids=[device.index] if device.type == "cuda" else None, find_unused_parameters=True)

    best_path = out / "best.pt"

    def checkpoint(next_epoch: int, stage: str) -> dict[str, Any]:
        opt_states = {name: o.state_dict() for name, o in optimizers.items()}
        train_state = {
            # one optimiser keeps the original "optimizer" key, so older readers still resume
            **({"optimizer": opt_states["optimizer"]} if list(opt_states) == ["optimizer"] else {}),
            "optimizers": opt_states,
            "next_epoch": next_epoch,
            "stage": stage,  # the phase the weights come from (e.g. Gesticulator's pre-training vs autoregressive)
            "history": history,
            "best_val": best,
            "rng_cpu": torch.get_rng_state(),
            "rng_cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
            "train_config": json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        }
        state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
        return make_checkpoint(cfg.model, dataclasses.asdict(mcfg), fcfg.to_dict(), norm.to_dict(), state, train_state)

    bar = _progress(info.is_main)
    before_step, sync = getattr(spec, "before_step", None), D.sync_of(info)
    for epoch in range(start, cfg.epochs):
        stage = spec.stage_name(epoch, mcfg) if hasattr(spec, "stage_name") else ""
        t_ep = time.perf_counter()
        g = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
        batches = _batches(len(xs), cfg.batch_size, g, info)
        net.train()
        total, count = 0.0, 0
        parts: dict[str, float] = {}
        what = f"epoch {epoch + 1}/{cfg.epochs}" + (f" [{stage}]" if stage else "")
        task = bar.add_task(what, total=len(batches), loss="-") if bar else None
        if bar and epoch == start:
            bar.start()
        for b in batches:
            xb, yb = torch.from_numpy(xs[b]).to(device), torch.from_numpy(ys[b]).to(device)  # read from disk
            if before_step is not None:
                with torch.no_grad():
                    before_step(model, xb, yb, epoch, mcfg, sync)
            if custom_step:
                stats = spec.train_step(net, optimizers, xb, yb, epoch, mcfg)
                batch_loss = float(stats["loss"])
                for k, v in stats.items():
                    parts[k] = parts.get(k, 0.0) + float(v) * len(b)
            else:
                opt = optimizers["optimizer"]
                loss = spec.loss(net, xb, yb, epoch, mcfg)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                batch_loss = float(loss.detach())
            total += batch_loss * len(b)
            count += len(b)
            if bar:
                bar.update(task, advance=1, loss=f"{total / count:.4f}")
        if bar:
            bar.remove_task(task)
        val = _evaluate(spec, model, vx, vy, epoch, mcfg, device, cfg.batch_size, info, torch)
        train_loss = D.all_reduce_mean([total / max(count, 1)], info, device)[0]
        part_means = dict(
            zip(parts, D.all_reduce_mean([v / max(count, 1) for v in parts.values()], info, device), strict=True)
        )
        entry = dataclasses.asdict(EpochLog(epoch + 1, train_loss, val, time.perf_counter() - t_ep, part_means))
        if not entry["parts"]:
            del entry["parts"]  # plain specs keep their history format
        if stage:
            entry["stage"] = stage
        history.append(entry)
        score = val if not math.isnan(val) else train_loss
        improved = epoch >= first_best and score < best
        best = score if improved else best
        if info.is_main:
            ckpt = checkpoint(epoch + 1, stage)
            save_checkpoint(ckpt, out / "last.pt")
            if epoch >= first_best and (improved or not best_path.is_file()):  # never a warm-up stage's model
                save_checkpoint(ckpt, best_path)
            with atomic_path(out / "history.json") as tmp:
                tmp.write_text(json.dumps(to_jsonable(history), indent=1, allow_nan=False), encoding="utf-8")
        say(
            f"{what}  train {train_loss:.4f}  val {val:.4f}  "
            f"{history[-1]['seconds']:.1f} s{'  *best' if improved else ''}"
        )
    if bar:
        bar.stop()
    return best_path


def _windows(spec, mcfg, train_takes, val_takes, norm, seq, cfg: TrainConfig, v_len, info: D.DistInfo):
    """Training ``(N, seq, ·)`` and validation ``(M, v_len, ·)`` windows, memory-mapped from files that each node's
    first rank writes under ``out`` and the other ranks map (:func:`robogest.learn.dist.builder_first`); the files
    are unlinked once every rank has mapped them, so they vanish with the run (as anonymous temporary files do).
    """
    import inspect
    import shutil
    import socket

    stride, out = cfg.window_stride, Path(cfg.out)
    store = out / f".windows-{socket.gethostname()}-{os.getpid() if not info.enabled else 'ddp'}"
    make = getattr(spec, "make_windows", None)
    kw = {}
    if make is not None and "cache_dir" in inspect.signature(make).parameters:
        from robogest.data.datasets import default_cache_dir

        kw["cache_dir"] = Path(cfg.cache_dir) if cfg.cache_dir else default_cache_dir()

    def cut(takes, length, step, name):
        if make is not None:
            return make(takes, norm, mcfg, length, step, store=store / name, **kw)[:2]
        return make_windows(takes, norm, length, step, store=store / name)[:2]

    def read():  # writes the windows where they are missing
        return (*cut(train_takes, seq, stride, "train"), *cut(val_takes, v_len, v_len // 2, "val"))

    def build():
        shutil.rmtree(store, ignore_errors=True)  # a crashed run's leftovers
        return read()

    warm = getattr(spec, "warm_cache", None)
    if warm is not None and kw and info.world_size > 1:  # every rank fills the cache for its share of the takes
        warm([*train_takes, *val_takes], mcfg, kw["cache_dir"], info.rank, info.world_size)
        D.barrier(info)
    arrays = D.builder_first(info, build, read)
    D.barrier(info)  # every rank has mapped them
    if info.local_rank == 0:
        shutil.rmtree(store, ignore_errors=True)
    return arrays


def _evaluate(spec, model, vx, vy, epoch, mcfg, device, batch, info, torch) -> float:
    """Mean validation loss (rank 0 evaluates everything; NaN without validation windows)."""
    if vx.shape[0] == 0:
        return math.nan
    loss = getattr(spec, "validation_loss", spec.loss)
    model.eval()
    total = 0.0
    with torch.no_grad():
        for s in range(0, vx.shape[0], batch):
            xb, yb = torch.from_numpy(vx[s : s + batch]).to(device), torch.from_numpy(vy[s : s + batch]).to(device)
            total += float(loss(model, xb, yb, epoch, mcfg)) * xb.shape[0]
    return total / vx.shape[0]
