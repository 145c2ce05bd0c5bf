"""Each generator declares what it can do (``Generator.capabilities``); the learned ones stay batch-only."""

from __future__ import annotations

import pytest

from robogest.generators.base import Capabilities, Generator


def test_rhythm_declares_streaming_a_live_plan_and_rest_windows():
    from robogest.generators.rhythm import RhythmGenerator

    assert RhythmGenerator.capabilities == Capabilities(streaming=True, live_plan=True, rest_windows=True)


@pytest.mark.parametrize(
    "module, cls",
    [
        ("robogest.generators.learned.gesticulator.inference", "GesticulatorGenerator"),
        ("robogest.generators.learned.rhythmic.inference", "RhythmicGenerator"),
        ("robogest.generators.learned.s2ag.inference", "S2AGGenerator"),
    ],
)
def test_learned_generators_are_batch_only(module, cls):
    import importlib

    gen = getattr(importlib.import_module(module), cls)
    assert issubclass(gen, Generator) and not gen.capabilities.streaming and not gen.capabilities.live_plan


def test_a_capability_not_declared_is_an_error_naming_the_generator():
    class Plain(Generator):
        name = "plain"

        def generate(self, speech, seed=0):
            raise AssertionError("not called")

    with pytest.raises(NotImplementedError, match="'plain' does not declare rest_windows"):
        Plain().rest_windows(None)  # type: ignore[arg-type]
    with pytest.raises(NotImplementedError, match="'plain' does not declare live_plan"):
        Plain().new_live_plan(0.1)
