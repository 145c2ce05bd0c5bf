"""Hand-made Speech objects, so generator tests need neither audio files nor the speech front-end."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.speech.types import Speech, SpeechFeatures, Word


def syllable_bursts(duration_s: float, beats_s: list[float], sr: int = 16000) -> np.ndarray:
    """Audio ``(N,)`` with one voiced 'syllable' (200 Hz harmonics, 5 ms attack, 0.15 s decay) starting at each
    beat, so the generator's acoustic-beat detector finds a beat there."""
    t = np.arange(int(duration_s * sr)) / sr
    out = np.zeros_like(t)
    for b in beats_s:
        u = t - b
        on = (u >= 0) & (u < 0.2)
        env = np.clip(u[on] / 0.005, 0, 1) * np.exp(-u[on] / 0.08)
        out[on] += 0.3 * env * sum(np.sin(2 * np.pi * 200 * k * u[on]) / k for k in range(1, 10))
    return out.astype(np.float32)


def build_speech(
    duration_s: float,
    beats_s: list[float],
    silent_spans: list[tuple[float, float]],
    words: list[tuple[str, float, float]] = (),
    fps: float = 20.0,
    sr: int = 16000,
) -> Speech:
    n = int(np.ceil(duration_s * fps))
    t = np.arange(n) / fps
    silence = np.zeros(n, dtype=bool)
    for a, b in silent_spans:
        silence |= (t >= a) & (t < b)
    rng = np.random.default_rng(1)
    rms = np.where(silence, 1e-4, 0.05 + 0.05 * rng.random(n))
    for b in beats_s:  # louder around beats
        rms[np.abs(t - b) < 0.06] *= 2.5
    pitch = np.where(silence, 0.0, 120 + 30 * np.sin(t))
    feats = SpeechFeatures(
        fps=fps, mel_db=np.zeros((n, 64)), mfcc=np.zeros((n, 37)), rms=rms, pitch_hz=pitch,
        word_features=np.zeros((n, 5)), filler=np.zeros(n, bool), silence=silence,
    )  # fmt: skip
    return Speech(
        audio=syllable_bursts(duration_s, beats_s, sr), sr=sr,
        words=tuple(Word(w, a, b) for w, a, b in words), beats_s=np.asarray(beats_s, dtype=float),
        beat_is_pseudo=np.zeros(len(beats_s), bool), silent_spans=tuple(silent_spans), noise_level=1e-4,
        features=feats, source="test",
    )  # fmt: skip


@pytest.fixture
def speech_with_pause() -> Speech:
    """0–0.6 s silent, speech to 3.0 s, a 1.6 s pause, speech to 6.5 s, 1.5 s trailing silence."""
    beats = [0.8, 1.25, 1.7, 2.2, 2.7, 4.9, 5.35, 5.8, 6.3]
    words = [("so", 0.7, 0.95), ("you", 1.2, 1.4), ("think", 1.45, 1.8), ("this", 1.85, 2.1), ("is", 2.15, 2.3),
             ("big", 2.6, 2.95), ("no", 4.8, 5.1), ("i", 5.3, 5.4), ("know", 5.45, 5.9), ("it", 6.0, 6.4)]  # fmt: skip
    return build_speech(8.0, beats, [(0.0, 0.6), (3.0, 4.6), (6.5, 8.0)], words)
