"""Per-utterance body language: ``style``, ``amount`` and ``gestures`` of one ``say`` or ``stream``.

The same three controls as the CLI's ``--style``, ``--amount`` and ``--gestures`` (options of the ``rhythm``
generator), given per call; they override the session's defaults for that utterance only. Checked on the caller's
thread (a bad value is one line naming the field); the generator itself is built where the utterance is prepared.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robogest.errors import InputError

#: Named styles: the ``amount`` each stands for (the CLI's ``--style``).
STYLES = {"calm": 0.5, "neutral": 1.0, "lively": 1.5}


@dataclass(frozen=True)
class BodyLanguage:
    """Checked per-call overrides; ``None`` fields keep the session's value.

    amount : gesture size and frequency in [0, 2] (``style`` resolved to it).
    gestures : ``"auto"`` (built-in units), ``"none"`` (idle breathing and rest only), or a folder / YAML file of
        gesture units added to the built-in ones (a path on this machine).
    """

    amount: float | None = None
    gestures: str | None = None

    @property
    def empty(self) -> bool:
        return self.amount is None and self.gestures is None

    def options(self, session: dict) -> dict:
        """``make_generator("rhythm", ...)`` options: the session's ``session`` with these overrides."""
        opts = dict(session)
        if self.amount is not None:
            opts["amount"] = self.amount
        if self.gestures is not None:
            opts.pop("gestures", None)
            opts.pop("repertoire", None)
            if self.gestures == "none":
                opts["gestures"] = "none"
            elif self.gestures != "auto":
                from robogest.generators import lexicon as lx

                opts["repertoire"] = lx.repertoire_with(Path(self.gestures))
        return opts


def body_language(style: Any = None, amount: Any = None, gestures: Any = None, *, what: str = "say") -> BodyLanguage:
    """Check the per-call fields (``what`` names the call in messages); InputError naming the bad field."""
    if style is not None and amount is not None:
        raise InputError(f'{what}: give "style" or "amount", not both')
    if style is not None:
        if not isinstance(style, str) or style not in STYLES:
            names = ", ".join(sorted(STYLES))
            raise InputError(f'{what}: "style" {style!r} is not one of {names}')
        amount = STYLES[style]
    if amount is not None:
        ok = isinstance(amount, int | float) and not isinstance(amount, bool) and math.isfinite(amount)
        if not ok or not 0.0 <= amount <= 2.0:
            raise InputError(f'{what}: "amount" must be a number within [0, 2] (0: no gestures), got {amount!r}')
        amount = float(amount)
    if gestures is not None:
        if not isinstance(gestures, str) or not gestures:
            raise InputError(f'{what}: "gestures" must be "auto", "none" or a folder or YAML file of gesture units')
        if gestures not in ("auto", "none") and not Path(gestures).exists():
            raise InputError(
                f'{what}: "gestures" {gestures}: no such folder or file; give "auto", "none" or a folder of '
                "gesture YAMLs"
            )
    return BodyLanguage(amount, gestures)
