"""The generator seam: speech in, canonical human motion out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Protocol

from robogest.motion.human_motion import HumanMotion
from robogest.registry import Registry
from robogest.speech.types import Speech


@dataclass(frozen=True)
class Capabilities:
    """What a generator can do beyond :meth:`Generator.generate`; the streaming planner reads only this.

    Attributes
    ----------
    streaming : bool
        ``generate`` works on a prefix of an utterance (speech still arriving), so a live stream may use it.
    live_plan : bool
        It shares one plan across a stream's plans (:meth:`Generator.new_live_plan`,
        :meth:`Generator.generate_live`): strokes already played stay, new ones start after them.
    rest_windows : bool
        :meth:`Generator.rest_windows` gives the spans in which its motion is exactly the rest pose (the planner
        pins those frames to rest).
    """

    streaming: bool = False
    live_plan: bool = False
    rest_windows: bool = False


class LivePlanState(Protocol):
    """The part of a generator's live plan the streaming planner sets: the time up to which frames are played."""

    commit_s: float


class Generator(ABC):
    """Turns a :class:`Speech` into a :class:`HumanMotion` on the canonical skeleton.

    Output frame ``t`` is at ``t / speech.fps`` seconds and the motion lasts as long as the speech.
    The same speech and seed must give the same motion.
    """

    name: str = ""
    #: What it can do (batch only by default); each generator declares its own.
    capabilities: ClassVar[Capabilities] = Capabilities()

    @property
    def annotations(self) -> dict:
        """What the last :meth:`generate` decided that evaluation can use, as named numeric arrays (e.g. the
        Rhythmic Gesticulator's per-block ``lexemes`` and lexicon size ``n_lexemes``); empty by default. The
        pipeline stores them in the trajectory so that ``robogest eval`` finds them in a saved file."""
        return dict(getattr(self, "_annotations", {}))

    @abstractmethod
    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion for ``speech``; ``seed`` fixes every random choice."""

    def rest_windows(self, speech: Speech) -> list[tuple[float, float]]:
        """Spans ``(t0_s, t1_s)`` in which the motion is exactly the rest pose (``capabilities.rest_windows``)."""
        raise NotImplementedError(f"generator {self.name!r} does not declare rest_windows in its capabilities")

    def new_live_plan(self, replan_s: float) -> LivePlanState:
        """A plan shared by one stream's calls of :meth:`generate_live` (``capabilities.live_plan``), ``replan_s``
        seconds between plans."""
        raise NotImplementedError(f"generator {self.name!r} does not declare live_plan in its capabilities")

    def generate_live(self, speech: Speech, live: LivePlanState, seed: int = 0) -> HumanMotion:
        """One plan of a stream: :meth:`generate` sharing ``live`` (from :meth:`new_live_plan`) with the others."""
        raise NotImplementedError(f"generator {self.name!r} does not declare live_plan in its capabilities")


GeneratorFactory = Callable[..., Generator]
#: Generators by name; factories take the generator's own keyword options (e.g. ``checkpoint``). Installed
#: packages add more through the ``robogest.generators`` entry-point group.
GENERATORS: Registry[GeneratorFactory] = Registry("generator", entry_point_group="robogest.generators")
register_generator = GENERATORS.register
generator_names = GENERATORS.names


def make_generator(name: str, **kwargs: object) -> Generator:
    return GENERATORS.get(name)(**kwargs)
