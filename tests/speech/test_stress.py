"""Where a word's stressed syllable falls (eSpeak NG's lexicon), and how close that is on real speech."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from robogest.speech.stress import phonemes, stress_fraction

from .conftest import BEAT2


def test_phonemes_mark_the_stressed_vowel():
    assert phonemes("about") == ["ɐ", "b", "ˈaʊ", "t"]
    assert phonemes("  ") == []
    assert len(phonemes("42")) > 4  # "forty two": every clause is read


def test_fraction_follows_the_stressed_syllable():
    # t ˈeɪ b əl: one consonant before the vowel, of 1 + 2 + 1 + 2 phoneme weights
    assert stress_fraction("table") == pytest.approx(1 / 6)
    assert stress_fraction("about") == pytest.approx(0.5)
    assert stress_fraction("table") < stress_fraction("about") < stress_fraction("understand") < 1.0
    assert stress_fraction("the") is None  # eSpeak stresses no syllable of most function words
    assert stress_fraction("") is None


def test_fraction_is_safe_from_several_threads():
    words = ["about", "remember", "important", "photography", "because"] * 20
    want = [stress_fraction.__wrapped__(w) for w in words]
    got: list[list[float | None]] = []

    def work() -> None:
        got.append([stress_fraction.__wrapped__(w) for w in words])

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == [want] * 4


@pytest.mark.shared
def test_fraction_places_stressed_vowels_of_real_speech():
    """On the BEAT2 take's words that carry a stressed vowel (its forced alignment, ARPAbet stress 1/2), the
    estimate ``start + fraction x duration`` is nearer the vowel's onset than a fixed 0.08 s after the start."""
    from robogest.speech.transcript import read_stressed_vowels, read_transcript

    tg = BEAT2.with_suffix(".TextGrid")
    if not tg.is_file():
        pytest.skip(f"BEAT2 sample not found under {BEAT2.parent}")
    vowels = read_stressed_vowels(tg)
    est, fixed = [], []
    for w in read_transcript(tg).words:
        v = vowels[(vowels >= w.start_s - 0.02) & (vowels < w.end_s)]
        f = stress_fraction(w.text)
        if v.size and f is not None:
            est.append(v[0] - w.start_s - f * (w.end_s - w.start_s))
            fixed.append(v[0] - w.start_s - 0.08)
    est_err, fixed_err = np.abs(est), np.abs(fixed)
    assert len(est) > 120
    assert np.median(est_err) < 0.03 < np.median(fixed_err)
    assert est_err.mean() < 0.8 * fixed_err.mean()
