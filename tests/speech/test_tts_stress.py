"""Stressed-syllable onsets of synthesized speech from eSpeak NG's phoneme events (stroke-sync reference events)."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import MissingDependencyError
from robogest.speech import synthesize, synthesize_with_stress
from robogest.speech import tts as tts_mod
from robogest.speech.tts import LIQUID_NASAL_VOWEL_LAG_S, PhonemeEvent, lags_onset, stressed_vowel_onsets

pytest.importorskip("espeakng_loader")

TEXT = "Hello, today I am happy."


@pytest.fixture(scope="module")
def stressed():
    return synthesize_with_stress(TEXT)


def _fractions(speech, onsets) -> dict[str, list[float]]:
    """Where each word's stressed onsets lie, as fractions of the word's span."""
    return {
        w.text: [(t - w.start_s) / (w.end_s - w.start_s) for t in onsets if w.start_s <= t < w.end_s]
        for w in speech.words
    }


def test_stress_falls_on_the_dictionary_syllable(stressed):
    # heLLO and toDAY stress the second syllable, HAPpy the first. A stressed vowel is the longest part of its
    # word, so a second-syllable stress starts before the word's midpoint: after h@l / t@d (over a third of the
    # word), while HAPpy's starts right after its h (under a third).
    f = _fractions(*stressed)
    assert len(f["hello"]) == len(f["today"]) == len(f["happy"]) == 1
    assert f["hello"][0] > 0.33 and f["today"][0] > 0.33
    assert f["happy"][0] < 0.3
    assert f["i"] == []  # eSpeak demotes "I am" in the sentence (and reports no word event for "am")


def test_stressed_onsets_are_loud(stressed):
    speech, onsets = stressed
    sr = speech.sr
    level = [np.sqrt(np.mean(speech.audio[round(t * sr) : round((t + 0.06) * sr)] ** 2)) for t in onsets]
    in_words = np.concatenate([speech.audio[round(w.start_s * sr) : round(w.end_s * sr)] for w in speech.words])
    assert min(level) > np.sqrt(np.mean(in_words**2))  # every onset's 60 ms beat the words' average level


def test_speech_is_the_same_as_synthesize(stressed):
    # Phoneme events must not change the audio, and the onsets travel beside the Speech, never inside it, so a
    # generator gets identical input and gives identical output.
    from robogest.generators import make_generator

    plain = synthesize(TEXT)
    speech, _ = stressed
    assert np.array_equal(plain.audio, speech.audio)
    assert plain.words == speech.words and np.array_equal(plain.beats_s, speech.beats_s)
    gen = make_generator("rhythm")
    assert np.array_equal(gen.generate(plain, seed=3).positions(), gen.generate(speech, seed=3).positions())


def test_ellipsis_pause_shifts_the_later_onsets():
    speech, onsets = synthesize_with_stress("I said hello... and then I left.", pause_s=1.2)
    words = {w.text: w for w in speech.words}
    assert np.all(np.diff(onsets) > 0)
    after = onsets[onsets > words["hello"].end_s]
    assert after.size >= 1 and after[0] >= words["and"].start_s - 0.05
    assert all(any(w.start_s - 0.03 <= t < w.end_s for w in speech.words) for t in onsets)


def test_stress_marks_and_liquid_lag():
    ev = [PhonemeEvent(0, 0, "h"), PhonemeEvent(100, 0, "@"), PhonemeEvent(200, 0, "l"), PhonemeEvent(300, 0, "'oU"),
          PhonemeEvent(400, 6, "h"), PhonemeEvent(500, 6, ",a"), PhonemeEvent(600, 6, "p")]  # fmt: skip
    assert [e.stress for e in ev] == [0, 0, 0, 2, 0, 1, 0]
    assert lags_onset("l") and lags_onset("'n") and not lags_onset("h") and not lags_onset("@")
    np.testing.assert_allclose(stressed_vowel_onsets(ev, 1000), [0.3 - LIQUID_NASAL_VOWEL_LAG_S, 0.5])


def test_build_without_stress_marks_is_named(monkeypatch):
    header = {"events": [], "phonemes": [[0, 0, "h"], [10, 0, "oU"]], "stress_marks": 1}
    monkeypatch.setattr(tts_mod, "_run_worker", lambda *a, **k: (np.zeros(20, np.float32), 22050, header))
    with pytest.raises(MissingDependencyError, match=r"phonemes without stress marks.*espeakng-loader"):
        tts_mod.espeak_synthesize_phonemes("hello")
