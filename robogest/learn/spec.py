"""What the trainer needs from a model family: :class:`ModelSpec`, five required methods and documented hooks.

A learned model's ``SPEC`` (``robogest/generators/learned/<model>/training.py``) subclasses :class:`ModelSpec`.
Every hook has a default that keeps the plain path (Adam on :meth:`ModelSpec.loss`, the trainer's standard
windows, no stages), so a spec overrides only what its model does differently; the trainer calls every hook
unconditionally and never asks whether a spec has one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

from robogest.data.prep import make_windows
from robogest.learn import require_torch

if TYPE_CHECKING:
    from robogest.data.datasets import Take
    from robogest.data.prep import Normalization
    from robogest.learn.dist import Sync
    from robogest.learn.trainer import TrainConfig

#: The model's config dataclass (e.g. ``GesticulatorConfig``).
C = TypeVar("C")


class ModelSpec(ABC, Generic[C]):
    """The trainer's view of one model family; subclass it and override the hooks the model needs.

    ``speech`` and ``poses`` are window batches ``(B, L, F)`` and ``(B, L, P)`` (torch tensors on the training
    device), ``epoch`` is 0-based, ``config`` the model's config (``C``). ``model`` is the ``torch.nn.Module`` of
    :meth:`build`, or under DistributedDataParallel its wrapper (in :meth:`loss` and :meth:`train_step`).

    Attributes
    ----------
    name : str
        Registered model name (``robogest train --model``).
    custom_step : bool
        Set for each subclass from whether it overrides :meth:`train_step` (not to be set by hand). A spec with its
        own step calls parts of the model directly, bypassing a DistributedDataParallel wrapper, so the trainer
        averages gradients by per-parameter hooks instead, and logs every value the step returns per epoch.
    """

    name: ClassVar[str]
    custom_step: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.custom_step = cls.train_step is not ModelSpec.train_step

    # -- required ---------------------------------------------------------------------------------------------------

    @abstractmethod
    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> C:
        """The model's config for these input/output sizes with the user's ``overrides`` (``--set``)."""

    @abstractmethod
    def config_from_dict(self, d: dict[str, Any]) -> C:
        """The config a checkpoint saved (``dataclasses.asdict``)."""

    @abstractmethod
    def build(self, config: C) -> Any:
        """A ``torch.nn.Module``."""

    @abstractmethod
    def sequence_length(self, config: C) -> int:
        """Frames per training window."""

    @abstractmethod
    def loss(self, model: Any, speech: Any, poses: Any, epoch: int, config: C) -> Any:
        """Scalar loss tensor of one batch at ``epoch``; also the validation loss unless :meth:`validation_loss`."""

    # -- configuration hooks (fresh runs only: a resumed run restores the config from its checkpoint) ---------------

    def fit_config(self, config: C, train_takes: Sequence[Take]) -> C:
        """Fill data-dependent config fields (speaker table, feature statistics) from the training takes."""
        return config

    def plan_epochs(self, config: C, epochs: int) -> C:
        """Fill epoch-dependent config fields (a schedule of training stages) from ``--epochs``."""
        return config

    def first_best_epoch(self, config: C) -> int:
        """Epochs before this one (0-based) never become ``best.pt`` (e.g. before every stage has trained)."""
        return 0

    def stage_name(self, epoch: int, config: C) -> str:
        """What the epoch trains, for the log line and ``history.json`` ("": no stages)."""
        return ""

    # -- data hooks -------------------------------------------------------------------------------------------------

    def make_windows(
        self, takes: Sequence[Take], norm: Normalization, config: C, length: int, stride: int,
        store: Path | None = None, cache_dir: Path | None = None,
    ) -> tuple[Any, Any, Any]:  # fmt: skip
        """Training arrays ``(N, L, F)``, ``(N, L, P)``, take index ``(N,)``.

        Default: :func:`robogest.data.prep.make_windows` (normalised mel+text, exp-map poses). A spec with other
        inputs or targets cuts its own; ``store`` goes to :func:`robogest.data.prep.slice_windows`, so DDP ranks
        map one copy; ``cache_dir`` is the run's cache folder, for window parts worth keeping across runs.
        """
        return make_windows(takes, norm, length, stride, store=store)

    def warm_cache(self, takes: Sequence[Take], config: C, cache_dir: Path, rank: int, world_size: int) -> None:
        """Under torchrun, before each node's first rank cuts the windows: fill ``cache_dir`` for this rank's share
        of ``takes``, so slow per-take work is spread over all ranks (default: nothing to warm)."""

    def validation_length(self, config: C) -> int:
        """Frames per held-out sequence (default :meth:`sequence_length`), e.g. several chained windows for a
        rollout that feeds its own outputs across windows."""
        return self.sequence_length(config)

    # -- step hooks -------------------------------------------------------------------------------------------------

    def make_optimizers(self, model: Any, train_config: TrainConfig, config: C) -> dict[str, Any]:
        """Named optimisers, all saved in and restored from checkpoints. Default: one Adam, ``"optimizer"``, at
        ``train_config.lr``, else the model config's ``lr`` (its paper's value), else 1e-4."""
        torch = require_torch()
        lr = train_config.lr if train_config.lr is not None else float(getattr(config, "lr", 1e-4))
        return {"optimizer": torch.optim.Adam(model.parameters(), lr=lr)}

    def before_step(self, model: Any, speech: Any, poses: Any, epoch: int, config: C, sync: Sync | None) -> None:
        """Update state not learned by gradient (e.g. a codebook's dead-code restarts) from this rank's batch, before
        its step, under ``no_grad``; ``sync`` (None alone) makes the change the same on every rank. Called on every
        rank for every batch, so its collectives always match (default: nothing)."""

    def train_step(
        self, model: Any, optimizers: dict[str, Any], speech: Any, poses: Any, epoch: int, config: C
    ) -> dict[str, float]:
        """One batch including ``zero_grad``/``backward``/``step``; returns ``"loss"`` (the train loss logged) and,
        in an override, more named values averaged per epoch into ``history.json``. Default: one step of the
        ``"optimizer"`` on :meth:`loss`."""
        opt = optimizers["optimizer"]
        loss = self.loss(model, speech, poses, epoch, config)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return {"loss": float(loss.detach())}

    def validation_loss(self, model: Any, speech: Any, poses: Any, epoch: int, config: C) -> Any:
        """The held-out loss ``best.pt`` is chosen on (default :meth:`loss`); e.g. an autoregressive model's
        free-running rollout (its own outputs fed back, as at run time) instead of a teacher-forced one."""
        return self.loss(model, speech, poses, epoch, config)
