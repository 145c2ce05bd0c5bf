"""Training stack shared by the learned generators: trainer, checkpoints, DDP, model options.

The models themselves live in :mod:`robogest.generators.learned`; the trainer receives a model's spec from its
caller (the ``robogest train`` command), so nothing here names a generator.

Torch lives in the optional extra ``robogest[learn]``; this package imports it only through
:func:`require_torch`, which turns its absence into a :class:`~robogest.errors.MissingDependencyError` that says
what to install.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from robogest.errors import InputError, MissingDependencyError


def require_torch(what: str = "learned generators") -> Any:
    """The ``torch`` module, or a :class:`MissingDependencyError` naming the extra to install."""
    try:
        import torch
    except ImportError:
        from robogest.extras import install_command

        raise MissingDependencyError(
            f"{what} need PyTorch, which is not installed; install it with: {install_command('learn')}"
        ) from None
    return torch


def config_with_overrides(cls: type, model: str, overrides: dict[str, Any], **fixed: Any) -> Any:
    """``cls`` (a model config dataclass) from its defaults, user ``overrides`` and the data's ``fixed`` sizes.

    Overrides come from ``robogest train --set KEY=VALUE`` or :attr:`TrainConfig.model_overrides`; each must name
    a field of ``cls`` and have the type of its default (an int is accepted for a float, a list for a tuple).

    Raises
    ------
    InputError
        Unknown option, or a value of the wrong type; the message names the model, the option and the value.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    bad = sorted(set(overrides) - set(fields))
    if bad:
        raise InputError(f"unknown {model} option(s): {', '.join(bad)}; options are {', '.join(sorted(fields))}")
    values = {}
    for key, value in overrides.items():
        f = fields[key]
        factory = f.default_factory  # every model config field has a default or a factory
        default = f.default if f.default is not dataclasses.MISSING else factory() if callable(factory) else None
        values[key] = _coerce(model, key, value, default)
    try:
        return cls(**{**values, **fixed})
    except ValueError as e:  # the config's own consistency checks (e.g. a window too short for its inputs)
        raise InputError(f"{model} options: {e}") from None


def _coerce(model: str, key: str, value: Any, default: Any) -> Any:
    kind = type(default)
    ok = {
        bool: isinstance(value, bool),
        int: isinstance(value, int) and not isinstance(value, bool),
        float: isinstance(value, int | float) and not isinstance(value, bool),
        str: isinstance(value, str),
        tuple: isinstance(value, list | tuple),
    }.get(kind, True)
    if not ok:
        raise InputError(f"{model} option {key}={value!r}: expected {kind.__name__} (default {default!r})")
    if kind in (int, float):  # every numeric model option is a size, count, rate, weight or probability
        if not math.isfinite(value) or value < 0:
            raise InputError(f"{model} option {key}={value!r}: expected a finite number >= 0 (default {default!r})")
        if "dropout" in key and not value < 1:
            raise InputError(f"{model} option {key}={value!r}: a dropout probability is below 1 (default {default!r})")
        if key.startswith("lr") and not value > 0:
            raise InputError(f"{model} option {key}={value!r}: a learning rate is above 0 (default {default!r})")
    if kind is float:
        return float(value)
    if kind is tuple:
        return tuple(value)
    return value


__all__ = ["config_with_overrides", "require_torch"]
