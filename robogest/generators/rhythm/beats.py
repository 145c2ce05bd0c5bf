"""Where strokes may land (acoustic beats plus unheard-by-the-detector stressed syllables) and where the motion
rests (long silent periods)."""

from __future__ import annotations

import numpy as np

from robogest.generators.acoustic import AcousticBeats, acoustic_beats
from robogest.generators.rhythm.config import RhythmConfig
from robogest.speech.stress import stress_fraction
from robogest.speech.types import Speech, Word

#: Live plans: a word whose stressed syllable has not been heard yet is expected to bring a beat this long after
#: that syllable's estimated onset (:func:`~robogest.speech.stress.stress_fraction` of the word's span), seconds.
#: Calibrated on the BEAT2 calibration half only, streamed at real time, 6 seeds: -0.03 / 0 / +0.03 s gave
#: stroke-sync z 3.27 / 3.51 / 3.08 (word-start beats: 2.42), with a word counted as heard 0.1 s after its
#: start; counted as heard only 0.1 s after its stressed syllable, 0 s gave 4.14 (offline 3.99).
STRESS_BEAT_S = 0.0
#: Offline, when words are known, a word's stressed syllable (:meth:`RhythmGenerator.stressed_syllable_s`) with no
#: acoustic beat within this many seconds of it is a beat too, of prominence :data:`STRESS_PROMINENCE`: the onset
#: detector misses stresses carried by pitch or length more than loudness. Calibrated on the BEAT2 calibration half
#: only (``bench_generalize.py --calibration-only --no-robot``, 10 seeds; human-motion stroke-sync z 4.32 without):
#: 0.06 / 0.12 / 0.16 / 0.2 s gave 4.66 / 4.86 / 4.59 / 4.31; prominence 0.3 / 0.5 / 0.7 gave 4.41 / 4.86 / 4.39; a
#: beat only in words with no acoustic beat at all 4.14; moving the nearest acoustic beat onto the syllable 3.76-4.00.
STRESS_NEAR_S = 0.12
STRESS_PROMINENCE = 0.5
#: A beat is heard about this long after it starts (a rise 0.05 s in, confirmed 0.05 s later), seconds.
HEARD_AFTER_S = 0.1


def rest_windows(c: RhythmConfig, speech: Speech) -> list[tuple[float, float]]:
    """Spans ``(t0, t1)`` in which the motion is exactly the rest pose."""
    out = []
    for a, b in speech.silent_spans:
        if b - a < c.min_rest_span_s and a > 1e-6:
            continue  # short pause mid-speech: hold the ready pose instead (a leading one is spent at rest)
        t0 = a if a <= 1e-6 else a + c.retract_s  # the motion starts at rest
        t1 = b if b >= speech.duration_s - 1e-6 else b - c.rest_lead_s
        if t1 > t0:
            out.append((t0, t1))
    return out


def stressed_syllable_s(w: Word) -> float | None:
    """Where word ``w``'s stressed syllable starts, s: its span shared among its phonemes in eSpeak NG's
    lexicon (:func:`~robogest.speech.stress.stress_fraction`) plus :data:`STRESS_BEAT_S`; None when eSpeak
    stresses none of its syllables."""
    f = stress_fraction(w.text)
    return None if f is None else w.start_s + f * (w.end_s - w.start_s) + STRESS_BEAT_S


def speech_beats(speech: Speech, loudness_db: np.ndarray | None = None, stressed: bool = True) -> AcousticBeats:
    """Where strokes may land: :func:`acoustic.acoustic_beats` of the speech, outside silent periods
    (``loudness_db``: its :func:`acoustic.band_loudness_db`, if already computed), judged against the levels
    of the audio heard (:attr:`Speech.heard_s`); and if ``stressed``, the stressed syllables of the words (heard)
    with no acoustic beat within :data:`STRESS_NEAR_S`.

    A live plan passes ``stressed=False``: it expects a beat on each word's stressed syllable until that is
    heard instead (:func:`~robogest.generators.rhythm.live.expected_beats`); giving heard words these beats too
    lowered its stroke sync (BEAT2 calibration half, real time, 10 seeds: 4.11 -> 3.33).
    """
    ab = acoustic_beats(
        speech.audio, speech.sr, tuple(speech.silent_spans), loudness_db=loudness_db, heard_s=speech.heard_s
    )
    upto = speech.duration_s if speech.heard_s is None else speech.heard_s - HEARD_AFTER_S
    syls = [stressed_syllable_s(w) for w in speech.words] if stressed else []
    extra = [s for s in syls if s is not None and 0 <= s < upto and np.all(np.abs(ab.t_s - s) >= STRESS_NEAR_S)]
    if not extra:
        return ab
    t = np.concatenate([ab.t_s, extra])
    order = np.argsort(t, kind="stable")
    return AcousticBeats(t[order], np.concatenate([ab.prominence, np.full(len(extra), STRESS_PROMINENCE)])[order])
