"""The trainer's view of Gesticulator (:class:`robogest.learn.spec.ModelSpec`): config, network, loss."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from robogest.data.datasets import Take
from robogest.data.prep import Normalization
from robogest.generators.learned.gesticulator.model import (
    GesticulatorConfig,
    GesticulatorNet,
    gesture_loss,
    teacher_forcing_period,
)
from robogest.generators.learned.gesticulator.pca import fit_pose_pca
from robogest.learn import config_with_overrides
from robogest.learn.spec import ModelSpec

if TYPE_CHECKING:
    from torch import Tensor, nn


class GesticulatorSpec(ModelSpec[GesticulatorConfig]):
    """The trainer's view of the model (:class:`robogest.learn.spec.ModelSpec`)."""

    name = "gesticulator"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> GesticulatorConfig:
        config: GesticulatorConfig = config_with_overrides(
            GesticulatorConfig, "gesticulator", overrides, n_acoustic=n_acoustic, n_text=n_text, n_pose=n_pose
        )
        return config

    def fit_config(self, config: GesticulatorConfig, train_takes: Sequence[Take]) -> GesticulatorConfig:
        """With ``pca_variance`` > 0, the PCA basis of the training takes' normalised poses (the trainer's own
        normalisation of the same takes), so validation and test poses never shape the output space."""
        if config.pca_variance == 0.0:
            return config
        norm = Normalization.fit(train_takes)
        components, _ = fit_pose_pca((norm.pose(t.poses) for t in train_takes), config.pca_variance)
        return dataclasses.replace(config, pca_components=tuple(tuple(row) for row in components.tolist()))

    def config_from_dict(self, d: dict[str, Any]) -> GesticulatorConfig:
        return GesticulatorConfig.from_dict(d)

    def build(self, config: GesticulatorConfig) -> GesticulatorNet:
        return GesticulatorNet(config)

    def sequence_length(self, config: GesticulatorConfig) -> int:
        return config.sequence_length

    def first_best_epoch(self, config: GesticulatorConfig) -> int:
        """Pre-training epochs (no autoregression, FiLM weights still zero) are the paper's No-Autoregression
        ablation, never the model ``best.pt`` hands to generation."""
        return config.pretrain_epochs

    def stage_name(self, epoch: int, config: GesticulatorConfig) -> str:
        period = teacher_forcing_period(epoch, config.pretrain_epochs)
        if period is None:
            return "pre-training, no autoregression"
        if period == 0:
            return "autoregressive, own poses only"
        if period == 1:
            return "autoregressive, full teacher forcing"
        return f"autoregressive, ground truth every {period} frames"

    def loss(self, model: nn.Module, speech: Tensor, poses: Tensor, epoch: int, config: GesticulatorConfig) -> Tensor:
        """Loss on the central ``train_frames`` of ``(B, 70, ·)`` sequences at ``epoch``'s teacher forcing; ``model``
        is the :class:`GesticulatorNet` or, under torchrun, its DDP wrapper."""
        period = teacher_forcing_period(epoch, config.pretrain_epochs)
        pred = model(speech, poses, period)  # (B, 40, P)
        target = poses[:, config.past : config.past + pred.shape[1]]  # (B, 40, P)
        return gesture_loss(pred, target)

    def validation_loss(
        self, model: nn.Module, speech: Tensor, poses: Tensor, epoch: int, config: GesticulatorConfig
    ) -> Tensor:
        """Loss of a free-running rollout from the mean pose, at every epoch (the authors' validation): the model's
        own poses feed back as at run time, so ``best.pt`` is chosen on what generation will do, not on a
        teacher-forced score (which from epoch 11 on sees the ground truth every frame)."""
        pred = model(speech, None, period=1)  # no ground truth: period 1 feeds back its own poses
        target = poses[:, config.past : config.past + pred.shape[1]]
        return gesture_loss(pred, target)


SPEC = GesticulatorSpec()
