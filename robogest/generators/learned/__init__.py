"""Learned generators, one package each (``gesticulator/``, ``rhythmic/``, ``s2ag/``): config, networks, training
spec and inference; ``checkpoint.py`` is the generator every one of them builds on.

Adding a learned model means adding one folder with a ``SPEC`` (:class:`robogest.learn.spec.ModelSpec`) and a
:class:`~robogest.generators.learned.checkpoint.CheckpointGenerator` subclass, and naming it in :data:`MODEL_SPECS`
and the generator registry (:mod:`robogest.generators`). Importing this package does not import torch; the model
packages do.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.errors import InputError

if TYPE_CHECKING:
    from robogest.learn.spec import ModelSpec
    from robogest.learn.trainer import TrainConfig


def _gesticulator() -> ModelSpec:
    from robogest.generators.learned.gesticulator import SPEC

    return SPEC


def _rhythmic() -> ModelSpec:
    from robogest.generators.learned.rhythmic import SPEC

    return SPEC


def _s2ag() -> ModelSpec:
    from robogest.generators.learned.s2ag import SPEC

    return SPEC


#: Model name (``robogest train --model``) -> loader of its trainer spec (imports torch when called).
MODEL_SPECS: dict[str, Callable[[], ModelSpec]] = {"gesticulator": _gesticulator, "rhythmic": _rhythmic, "s2ag": _s2ag}


def model_names() -> list[str]:
    return sorted(MODEL_SPECS)


def get_model_spec(name: str) -> ModelSpec:
    """The trainer spec registered as ``name``.

    Raises
    ------
    InputError
        Unknown name; the message lists the known ones.
    """
    if name not in MODEL_SPECS:
        raise InputError(f"unknown model {name!r}; choose one of {', '.join(model_names())}")
    return MODEL_SPECS[name]()


def train_model(cfg: TrainConfig, log: Callable[[str], None] | None = None) -> Path:
    """:func:`robogest.learn.trainer.train` with the spec of ``cfg.model``; returns the best checkpoint's path."""
    from robogest.learn.trainer import train

    return train(cfg, get_model_spec(cfg.model), log)


__all__ = ["MODEL_SPECS", "get_model_spec", "model_names", "train_model"]
