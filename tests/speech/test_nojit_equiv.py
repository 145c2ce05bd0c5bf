"""The numpy/scipy front-end (:mod:`robogest.speech.dsp`) gives librosa's results on real and synthetic speech.

Each check calls librosa exactly as the front-end did before (same arguments), so a difference means the
replacement drifted (or a new librosa changed its method: then decide which to follow). librosa compiles its
numba kernels on first use, hence ``slow``. On librosa 0.11 / numpy 2.4 all results were bitwise equal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import soundfile as sf

from robogest.speech import dsp
from robogest.speech.config import SpeechConfig
from robogest.speech.features import log_mel_db, mel_hop_win

from .conftest import BEAT2, SR, quiet, syllables

librosa = pytest.importorskip("librosa")
pytestmark = pytest.mark.slow

CFG = SpeechConfig()


def _tts_16k() -> np.ndarray:
    pytest.importorskip("espeakng_loader")
    from robogest.speech.tts import espeak_synthesize

    audio, sr, _ = espeak_synthesize("Hello there, nice to meet you.")
    return dsp.resample(audio, sr, SR)


def _beat2() -> np.ndarray:
    wav = BEAT2.with_suffix(".wav")
    if not wav.is_file():
        pytest.skip(f"BEAT2 sample not found at {wav}")
    y, sr = sf.read(wav, dtype="float32")
    assert sr == SR
    return y


def _synthetic() -> np.ndarray:
    return np.concatenate([quiet(0.4), syllables(2.0), quiet(0.5, seed=1), syllables(1.3, rate_hz=5.0)])


SOURCES = {"synthetic": _synthetic, "tts": _tts_16k, "beat2": _beat2}


@pytest.fixture(scope="module", params=["synthetic", "tts", pytest.param("beat2", marks=pytest.mark.shared)])
def audio(request) -> np.ndarray:
    return SOURCES[request.param]()


def test_resample_matches_librosa():
    pytest.importorskip("espeakng_loader")
    from robogest.speech.tts import espeak_synthesize

    y, sr, _ = espeak_synthesize("Hello there, nice to meet you.")
    ref = librosa.resample(y, orig_sr=sr, target_sr=SR)
    got = dsp.resample(y, sr, SR)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)


def test_log_mel_and_mfcc_match_librosa(audio):
    hop, win = mel_hop_win(SR, CFG.fps, CFG.mel_window_s)
    mel = librosa.feature.melspectrogram(
        y=audio, sr=SR, n_fft=win, hop_length=hop, win_length=win, n_mels=CFG.n_mels, power=2.0,
        center=True, pad_mode="constant",
    )  # fmt: skip
    ref = librosa.power_to_db(mel, ref=1.0, amin=1e-10, top_db=None).T
    got = log_mel_db(audio, SR, hop, win, CFG.n_mels)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-3)  # dB
    ref_cep = librosa.feature.mfcc(S=ref.T, n_mfcc=13).T
    np.testing.assert_allclose(dsp.mfcc_from_db(ref, 13), ref_cep, rtol=1e-6, atol=1e-4)


def test_stacked_log_mel_matches_one_by_one(audio):
    """The learned generators analyse a stack of equally long signals at once."""
    hop, win = mel_hop_win(SR, CFG.fps, CFG.mel_window_s)
    stack = np.stack([audio, 0.5 * audio])
    got = log_mel_db(stack, SR, hop, win, CFG.n_mels, center=False)
    np.testing.assert_allclose(got[1], log_mel_db(0.5 * audio, SR, hop, win, CFG.n_mels, center=False), atol=1e-4)


def test_yin_matches_librosa(audio):
    hop, _ = mel_hop_win(SR, CFG.fps, CFG.mel_window_s)
    frame_length = 1 << math.ceil(math.log2(4.0 * SR / CFG.fmin_hz))
    ref = librosa.yin(
        audio, fmin=CFG.fmin_hz, fmax=CFG.fmax_hz, sr=SR, frame_length=frame_length, hop_length=hop,
        center=True, pad_mode="constant",
    )  # fmt: skip
    got = dsp.yin(audio, SR, CFG.fmin_hz, CFG.fmax_hz, frame_length, hop)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=1e-6)


def test_onset_envelope_and_peaks_match_librosa(audio):
    hop = round(CFG.onset_hop_s * SR)
    n_fft = 1 << max(8, math.ceil(math.log2(4 * hop)))
    ref = librosa.onset.onset_strength(y=audio, sr=SR, hop_length=hop, n_fft=n_fft, n_mels=40, fmax=SR / 2)
    got = dsp.onset_strength(audio, SR, hop, n_fft, n_mels=40)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)
    ref_on = librosa.onset.onset_detect(onset_envelope=ref, sr=SR, hop_length=hop, units="frames")
    np.testing.assert_array_equal(dsp.onset_detect(ref, SR, hop), ref_on)
    assert ref_on.size > 0
    # the streaming front-end: its own scale, no normalisation
    scaled = (ref - ref.min()) / (2.0 * float(ref.max() - ref.min()))
    ref_on = librosa.onset.onset_detect(onset_envelope=scaled, sr=SR, hop_length=hop, units="frames", normalize=False)
    np.testing.assert_array_equal(dsp.onset_detect(scaled, SR, hop, normalize=False), ref_on)


def test_peak_pick_matches_librosa_on_noise(rng):
    """Random envelopes exercise ties, plateaus and the wait rule far more than speech does."""
    for _ in range(20):
        x = rng.random(int(rng.integers(1, 400))).astype(np.float32)
        x[rng.random(x.shape[0]) < 0.2] = 0.5  # plateaus of equal values
        pre_max, post_max, pre_avg, post_avg, wait = (int(v) for v in rng.integers(1, 12, size=5))
        ref = librosa.util.peak_pick(x, pre_max=pre_max, post_max=post_max, pre_avg=pre_avg - 1,
                                     post_avg=post_avg, delta=0.05, wait=wait - 1)  # fmt: skip
        got = dsp.peak_pick(x, pre_max, post_max, pre_avg - 1, post_avg, float(np.float32(0.05)), wait - 1)
        np.testing.assert_array_equal(got, ref)


def test_frame_matches_librosa(audio):
    ref = librosa.util.frame(audio, frame_length=2048, hop_length=800, axis=0)
    np.testing.assert_array_equal(dsp.frame(audio, 2048, 800), ref)
