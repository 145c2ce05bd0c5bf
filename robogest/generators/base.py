"""The generator seam: speech in, canonical human motion out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

from robogest.motion.human_motion import HumanMotion
from robogest.registry import Registry
from robogest.speech.types import Speech


class Generator(ABC):
    """Turns a :class:`Speech` into a :class:`HumanMotion` on the canonical skeleton.

    Output frame ``t`` is at ``t / speech.fps`` seconds and the motion lasts as long as the speech.
    The same speech and seed must give the same motion.
    """

    name: str = ""

    @property
    def annotations(self) -> dict:
        """What the last :meth:`generate` decided that evaluation can use, as named numeric arrays (e.g. the
        Rhythmic Gesticulator's per-block ``lexemes`` and lexicon size ``n_lexemes``); empty by default. The
        pipeline stores them in the trajectory so that ``robogest eval`` finds them in a saved file."""
        return dict(getattr(self, "_annotations", {}))

    @abstractmethod
    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion for ``speech``; ``seed`` fixes every random choice."""


GeneratorFactory = Callable[..., Generator]
#: Generators by name; factories take the generator's own keyword options (e.g. ``checkpoint``). Installed
#: packages add more through the ``robogest.generators`` entry-point group.
GENERATORS: Registry[GeneratorFactory] = Registry("generator", entry_point_group="robogest.generators")
register_generator = GENERATORS.register
generator_names = GENERATORS.names


def make_generator(name: str, **kwargs: object) -> Generator:
    return GENERATORS.get(name)(**kwargs)
