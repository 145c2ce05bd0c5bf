"""Gesture generators: speech in, canonical human motion out. ``rhythm`` is the default.

The learned generators' factories pass their keyword options on unchecked (Any): each constructor checks its own.
"""

from typing import Any

from robogest.generators import rhythm as _rhythm  # noqa: F401  (registers "rhythm")
from robogest.generators.base import Generator, generator_names, make_generator, register_generator

DEFAULT_GENERATOR = "rhythm"


@register_generator("gesticulator")
def _gesticulator(**kwargs: Any) -> Generator:
    """Imported on request only: it needs torch (``pip install 'robogest[learn]'``)."""
    from robogest.generators.learned.gesticulator import GesticulatorGenerator

    return GesticulatorGenerator(**kwargs)


@register_generator("rhythmic")
def _rhythmic(**kwargs: Any) -> Generator:
    """Learned Rhythmic Gesticulator; imported on request only (needs torch)."""
    from robogest.generators.learned.rhythmic import RhythmicGenerator

    return RhythmicGenerator(**kwargs)


@register_generator("s2ag")
def _s2ag(**kwargs: Any) -> Generator:
    """Learned Speech2AffectiveGestures; imported on request only (needs torch)."""
    from robogest.generators.learned.s2ag import S2AGGenerator

    return S2AGGenerator(**kwargs)


__all__ = ["DEFAULT_GENERATOR", "Generator", "generator_names", "make_generator", "register_generator"]
