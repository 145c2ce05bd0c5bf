"""PMB, BeatAlign, motion-beat detection and the chance-corrected sync score."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.eval.beats import (
    beat_align,
    beat_sync_report,
    chance_corrected,
    motion_beats,
    pmb,
    pmb_curve,
    stroke_hit_rate,
    stroke_peaks,
    stroke_sync,
    stroke_sync_events,
)

FPS = 30.0


def audio_beats(rng, seconds: float = 60.0) -> np.ndarray:
    """Speech-like beats: intervals uniform in [0.2, 0.5] s (Rhythmic Gesticulator §4.2.1), ~2.9 beats/s."""
    b = np.cumsum(rng.uniform(0.2, 0.5, size=int(seconds / 0.2)))
    return b[b < seconds]


def test_pmb_exact_beats_is_100():
    b = np.array([0.5, 1.0, 1.7, 2.2])
    assert pmb(b, b) == 100.0


def test_pmb_counts_each_audio_beat_once_and_in_order():
    assert pmb(np.array([1.0, 1.05]), np.array([1.0])) == 50.0  # two motion beats cannot share one audio beat
    assert pmb(np.array([1.0, 3.0]), np.array([1.15, 5.0]), 0.2) == 50.0
    assert pmb(np.array([1.0]), np.array([1.25]), 0.2) == 0.0
    assert np.isnan(pmb(np.array([]), np.array([1.0])))


def test_pmb_curve_is_monotone():
    rng = np.random.default_rng(1)
    c = pmb_curve(np.sort(rng.uniform(0, 20, 40)), audio_beats(rng, 20))
    assert np.all(np.diff(c["pmb"]) >= 0)


def test_beat_align_closed_form():
    assert beat_align(np.array([1.0, 2.0]), np.array([1.0, 2.0])) == pytest.approx(1.0)
    # one audio beat 0.3 s from the only motion beat, σ = 0.3: exp(-1/2)
    assert beat_align(np.array([1.0]), np.array([1.3]), 0.3) == pytest.approx(np.exp(-0.5))
    assert beat_align(np.array([]), np.array([1.0])) == 0.0


def _speed_minima_motion(period_s: float, seconds: float) -> np.ndarray:
    """x(t) = -cos(π t / P): speed |sin(π t / P)| has its minima (motion beats) at t = k P."""
    t = np.arange(round(seconds * FPS) + 1) / FPS
    pos = np.zeros((t.size, 2, 3))
    pos[:, :, 0] = -0.1 * np.cos(np.pi * t / period_s)[:, None]
    return pos


def test_motion_beats_at_velocity_minima_give_pmb_100():
    pos = _speed_minima_motion(0.5, 10.0)
    mb = motion_beats(pos, FPS)
    expected = np.arange(1, 20) * 0.5  # interior minima only
    assert mb.size == expected.size
    assert np.allclose(mb, expected, atol=1.01 / FPS)
    assert pmb(mb, expected) == 100.0


def test_stroke_peaks_at_speed_maxima_of_each_wrist():
    pos = _speed_minima_motion(0.5, 10.0)
    pos[:, 1] *= 0.0  # the second wrist holds still: only the first one's peaks
    wp = stroke_peaks(pos, FPS)
    assert np.allclose(wp, np.arange(20) * 0.5 + 0.25, atol=1.01 / FPS)
    # drift slower than the prominence floor is no stroke
    assert stroke_peaks(pos * 0.01, FPS).size == 0


def test_still_motion_has_no_beats():
    assert motion_beats(np.zeros((100, 3, 3)), FPS).size == 0


def test_random_motion_beats_have_near_zero_z_despite_high_raw_pmb(rng):
    ab = audio_beats(rng)
    random_mb = np.sort(rng.uniform(0, 60, size=120))
    r = chance_corrected(lambda m, a: pmb(m, a, 0.2), random_mb, ab, 60.0)
    assert r["score"] > 50.0  # why raw PMB misleads: chance alone matches most beats
    assert abs(r["z"]) < 2.5
    assert r["n_shifts"] == 100


def test_aligned_motion_beats_have_large_z(rng):
    ab = audio_beats(rng)
    keep = rng.uniform(size=ab.size) < 0.7
    aligned = np.sort(ab[keep] + rng.normal(0, 0.03, size=keep.sum()))
    for fn in (lambda m, a: pmb(m, a, 0.2), lambda m, a: pmb(m, a, 0.1), beat_align):
        r = chance_corrected(fn, aligned, ab, 60.0)
        assert r["z"] > 3.0, r


def test_chance_correction_needs_room_to_shift():
    r = chance_corrected(pmb, np.array([1.0]), np.array([1.0]), 3.0)
    assert r["score"] == 100.0 and np.isnan(r["z"]) and r["n_shifts"] == 0


def test_beat_sync_report_on_beat_locked_motion():
    pos = _speed_minima_motion(0.5, 30.0)
    rng = np.random.default_rng(3)
    ab = np.arange(1, 60) * 0.5 + rng.normal(0, 0.01, 59)
    r = beat_sync_report(pos, FPS, ab, wrists=[0, 1], n_shifts=50, onsets_s=np.arange(60) * 0.5 + 0.35)
    assert r["pmb"]["score"] == pytest.approx(100.0)
    assert set(r) >= {"pmb", "beat_align", "stroke_sync", "pmb_curve", "n_motion_beats"}
    assert r["stroke_sync"]["hit"] == pytest.approx(1.0)
    assert "stroke_sync" not in beat_sync_report(pos, FPS, ab, wrists=[0, 1], n_shifts=50)
    # perfectly periodic motion vs periodic beats: shifting by whole periods also matches, so z stays modest
    # — the null captures exactly this rhythm-only agreement
    assert r["pmb"]["null_mean"] > 30.0


# --- stroke sync -------------------------------------------------------------------------------------------


def _strokes_at(times_s: np.ndarray, seconds: float, fps: float = FPS) -> np.ndarray:
    """Wrist positions ``(T, 2, 3)`` m whose speed has one 0.15 s-wide bump (a stroke) peaking at each time."""
    t = np.arange(round(seconds * fps)) / fps
    speed = np.zeros_like(t)
    for c in times_s:
        speed += 1.5 * np.exp(-0.5 * ((t - c) / 0.05) ** 2)  # m/s
    pos = np.zeros((t.size, 2, 3))
    pos[:, 0, 1] = np.cumsum(speed) / fps  # one wrist moves along y
    return pos


def test_stroke_hit_rate_closed_form():
    on = np.array([1.0, 2.0, 3.0])
    # an event 0..0.2 s after the peak is a hit; one before it or later than 0.2 s is not
    assert stroke_hit_rate(np.array([0.85, 1.05, 2.5]), on) == pytest.approx(1 / 3)
    assert stroke_hit_rate(np.array([0.85, 1.05, 2.5]), on, window_s=(-0.1, 0.16)) == pytest.approx(2 / 3)
    assert stroke_hit_rate(np.array([0.85, 2.5]), on, silent_spans=[(2.4, 2.6)]) == 1.0  # 2.5 is in a pause
    assert np.isnan(stroke_hit_rate(np.array([2.5]), on, silent_spans=[(2.0, 3.0)]))
    assert stroke_hit_rate(np.array([1.0]), np.array([])) == 0.0
    with pytest.raises(InputError, match=r"window \(0.2, 0.0\): the end must not precede"):
        stroke_hit_rate(np.array([1.0]), on, window_s=(0.2, 0.0))


def test_stroke_sync_strokes_leading_onsets_score_high(rng):
    on = audio_beats(rng, 40.0)
    strokes = np.sort(rng.choice(on, size=50, replace=False)) - 0.1  # speed peaks 0.1 s before the syllables
    r = stroke_sync(_strokes_at(strokes, 40.0), FPS, on, n_shifts=60)
    assert r["hit"] > 0.95 and r["z"] > 4.0, r
    assert r["n_peaks"] == 50 and r["n_onsets"] == on.size and r["n_shifts"] == 60


def test_stroke_sync_strokes_off_onsets_score_low(rng):
    on = audio_beats(rng, 40.0)
    strokes = np.arange(1.0, 39.0, 0.7)
    zs = [stroke_sync(_strokes_at(strokes + 0.13 * k, 40.0), FPS, on, n_shifts=60)["z"] for k in range(3)]
    assert abs(np.mean(zs)) < 1.5, zs
    # strokes lagging the onsets by 0.1 s (no onset in the 0.2 s after them): well below chance
    lag = on[:-1][np.diff(on) > 0.35] + 0.1
    assert stroke_sync(_strokes_at(lag[::2], 40.0), FPS, on, n_shifts=60)["z"] < -2.0


def test_stroke_sync_ignores_peaks_in_pauses(rng):
    on = np.arange(0.5, 20.0, 0.5)
    pause = [(5.0, 15.0)]
    strokes = np.concatenate([on[on < 5] - 0.1, np.arange(5.2, 15, 0.5)[:10]])  # off-onset peaks only in the pause
    r = stroke_sync(_strokes_at(strokes, 20.0), FPS, on, silent_spans=pause, n_shifts=30)
    assert r["hit"] == pytest.approx(1.0)
    assert r["n_peaks"] == int((on < 5).sum())


def test_stroke_sync_events_given_stressed_vowels_win(tmp_path):
    # Known stressed-vowel onsets (a TTS clip's) are used as they are, before any transcript or detector.
    tg = tmp_path / "x.TextGrid"
    tg.write_text("not a TextGrid")  # would raise if it were read
    audio = np.zeros(22050, dtype=np.float32)
    ev, kind = stroke_sync_events(audio, 22050, tg, stressed_vowels_s=np.array([0.9, 0.2, 0.5]))
    assert kind == "stressed_vowels" and ev.tolist() == [0.2, 0.5, 0.9]
    ev, kind = stroke_sync_events(audio, 22050)
    assert kind == "librosa_onsets" and ev.size == 0  # silence has no onsets
