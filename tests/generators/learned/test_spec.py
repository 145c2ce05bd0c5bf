"""The trainer's model interface (robogest.learn.spec.ModelSpec): required methods, hook defaults, own-step flag."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

pytest.importorskip("torch")


def _minimal():
    from robogest.learn.spec import ModelSpec

    class Minimal(ModelSpec[dict]):
        name = "minimal"

        def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> dict:
            return SimpleNamespace(lr=0.5, **overrides)  # the model config's lr: the default optimiser's

        def config_from_dict(self, d: dict[str, Any]) -> dict:
            return dict(d)

        def build(self, config: dict) -> Any:
            import torch

            return torch.nn.Linear(2, 2)

        def sequence_length(self, config: dict) -> int:
            return 7

        def loss(self, model: Any, speech: Any, poses: Any, epoch: int, config: dict) -> Any:
            return ((model(speech) - poses) ** 2).mean()

    return Minimal


def test_a_spec_without_a_required_method_cannot_be_made():
    from robogest.learn.spec import ModelSpec

    class NoLoss(ModelSpec[dict]):
        name = "noloss"

        def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> dict:
            return {}

        def config_from_dict(self, d: dict[str, Any]) -> dict:
            return d

        def build(self, config: dict) -> Any:
            return None

        def sequence_length(self, config: dict) -> int:
            return 1

    with pytest.raises(TypeError, match="loss"):
        NoLoss()


def test_hook_defaults_keep_the_plain_path():
    import torch

    from robogest.learn.trainer import TrainConfig

    spec = _minimal()()
    cfg = spec.make_config(1, 1, 1, {})
    assert spec.fit_config(cfg, []) is cfg and spec.plan_epochs(cfg, 5) is cfg
    assert spec.first_best_epoch(cfg) == 0 and spec.stage_name(3, cfg) == ""
    assert spec.validation_length(cfg) == spec.sequence_length(cfg) == 7
    assert not spec.custom_step
    model = spec.build(cfg)
    opts = spec.make_optimizers(model, TrainConfig(model="minimal"), cfg)  # lr None: the config's lr
    assert list(opts) == ["optimizer"] and opts["optimizer"].param_groups[0]["lr"] == 0.5
    opts = spec.make_optimizers(model, TrainConfig(model="minimal", lr=0.25), cfg)
    assert opts["optimizer"].param_groups[0]["lr"] == 0.25
    x, y = torch.ones(3, 2), torch.zeros(3, 2)
    before = spec.validation_loss(model, x, y, 0, cfg)
    stats = spec.train_step(model, opts, x, y, 0, cfg)
    assert stats["loss"] == pytest.approx(float(before.detach()))
    assert float(spec.loss(model, x, y, 0, cfg).detach()) < float(before.detach())  # it stepped


def test_own_step_is_detected_per_spec():
    from robogest.generators.learned import get_model_spec

    assert get_model_spec("s2ag").custom_step  # GAN: discriminator and generator steps
    assert not get_model_spec("gesticulator").custom_step
    assert not get_model_spec("rhythmic").custom_step

    class Own(_minimal()):
        def train_step(self, model, optimizers, speech, poses, epoch, config):
            return {"loss": 0.0}

    assert Own.custom_step and not _minimal().custom_step
