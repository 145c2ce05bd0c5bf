"""The rhythm generator's output, pinned: a refactor that changes the motion by more than rounding fails here.

The digests are of a hand-made speech (no eSpeak NG audio; the words' stressed syllables are pinned below, not
looked up), offline and as a live stream of five plans. If a change is meant to alter the motion, say so in its
commit and update the digests from the failure message."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from robogest.generators.rhythm import LivePlan, RhythmGenerator
from robogest.generators.rhythm import beats as rhythm_beats
from tests.generators.conftest import build_speech

OFFLINE_SHA256 = "8fb6f59ebe0e726688201aa7d82312a90c79828c3aa246aa0a64e26844527139"
LIVE_SHA256 = "ca6af6ee27e74662a84e0dbef36c25c4473c06e1b70dce62b654e2ef99912a30"

BEATS_S = [0.8, 1.25, 1.7, 2.2, 2.7, 3.3, 3.8, 4.9, 5.35, 5.8, 6.3, 6.9]
WORDS = [("so", 0.7, 0.95), ("you", 1.2, 1.4), ("think", 1.45, 1.8), ("this", 1.85, 2.1), ("is", 2.15, 2.3),
         ("big", 2.6, 2.95), ("right", 3.2, 3.6), ("no", 4.8, 5.1), ("i", 5.3, 5.4), ("know", 5.45, 5.9),
         ("it", 6.0, 6.4), ("maybe", 6.8, 7.2)]  # fmt: skip
TEXT = "So you ^gesture(point_away) think this is big, right? No, I know it, maybe."
#: Stressed-syllable fractions standing in for eSpeak NG's lexicon (None: a word with no stressed syllable).
STRESS = {"so": 0.3, "you": 0.35, "think": 0.25, "big": 0.3, "right": 0.3, "no": 0.4, "know": 0.3, "maybe": 0.2}


def digest(*arrays: np.ndarray) -> str:
    """sha256 of the arrays as float64 rounded to 1e-9 (-0.0 as 0.0)."""
    h = hashlib.sha256()
    for a in arrays:
        h.update((np.round(np.asarray(a, dtype=np.float64), 9) + 0.0).tobytes())
    return h.hexdigest()


@pytest.fixture
def speech(monkeypatch):
    monkeypatch.setattr(rhythm_beats, "stress_fraction", STRESS.get)
    sp = build_speech(8.0, BEATS_S, [(0.0, 0.6), (3.9, 4.6), (7.4, 8.0)], WORDS)
    return dataclasses.replace(sp, text=TEXT)


def test_offline_motion_is_pinned(speech):
    g = RhythmGenerator()
    rotations = [g.generate(speech, seed=s).rotations for s in (0, 5)]
    events = g.plan(speech, seed=0)
    assert {e.source.split(":")[0] for e in events} >= {"tag", "keyword", "beat"}  # every kind of choice is pinned
    assert digest(*rotations) == OFFLINE_SHA256


def test_live_motion_is_pinned(speech):
    """A stream planned every 0.25 s, each plan from 1 s before its committed frames, hearing the audio and
    knowing the words up to 0.15 s past them."""
    g = RhythmGenerator(fps=50.0)
    live = LivePlan(replan_s=0.25)
    out = []
    for commit_s in np.arange(0.5, 7.5, 0.25):
        live.commit_s = commit_s
        heard_s = commit_s + 0.15
        words = tuple(w for w in speech.words if w.start_s < heard_s)
        plan = dataclasses.replace(speech, heard_s=heard_s, words=words).crop(max(0.0, commit_s - 1.0))
        out.append(g.generate(plan, seed=2, live=live).rotations)
    assert any(scale > 0 for scale in live.placed.values()) and live.started and live.drift_s  # late strokes too
    placed = np.array(sorted((t, scale) for (t, _), scale in live.placed.items()))
    assert digest(*out, placed) == LIVE_SHA256
