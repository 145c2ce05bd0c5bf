"""The streaming front-end agrees with the batch one on the same audio, and never revises what it committed."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.speech import synthesize
from robogest.speech.audio import resample
from robogest.speech.stream import SpeechStream, stream_speech

TEXT = "Hello there, how are you today? ... I am fine, thanks for asking. Shall we start with the first topic?"


@pytest.fixture(scope="module")
def tts():
    return synthesize(TEXT)


def _matched(a: np.ndarray, b: np.ndarray, tol_s: float) -> float:
    """Fraction of ``a`` with an element of ``b`` within ``tol_s``."""
    return float(np.mean([np.min(np.abs(b - x)) <= tol_s for x in a])) if len(a) else 1.0


@pytest.mark.parametrize("sr", [16000, 24000])
def test_streamed_beats_and_silences_match_batch(tts, sr):
    audio = resample(tts.audio, tts.sr, sr)
    pcm = np.round(np.clip(audio, -1, 1) * 32767).astype(np.int16)  # what a voice agent sends
    st = stream_speech(pcm, sr, chunk_s=0.02)
    frame = 1.0 / tts.fps  # 50 ms
    assert abs(len(st.beats_s) - len(tts.beats_s)) <= 1
    assert _matched(tts.beats_s, st.beats_s, 2 * frame) >= 0.9
    assert _matched(st.beats_s, tts.beats_s, 2 * frame) >= 0.9
    assert len(st.silent_spans) == len(tts.silent_spans) == 1
    np.testing.assert_allclose(st.silent_spans, tts.silent_spans, atol=frame)
    assert st.n_frames == tts.n_frames
    np.testing.assert_allclose(st.features.rms, tts.features.rms, atol=2e-3)


def test_committed_beats_are_never_revised_and_trail_by_the_lookahead(tts):
    s = SpeechStream(tts.sr)
    snapshots = []
    for i in range(0, len(tts.audio), 480):
        if s.feed(tts.audio[i : i + 480]):
            assert s.beat_commit_s <= max(0.0, s.received_s - s.lookahead_s) + 1e-9
            snapshots.append(s.beats_s.copy())
    s.close()
    final = s.beats_s
    for snap in snapshots:
        np.testing.assert_array_equal(final[: len(snap)], snap)
    # during speech the commit point does not lag far behind (beats come at least every 0.5 s)
    mid = s.speech(pad_s=1.0)
    assert mid.duration_s == pytest.approx(s.received_s)  # closed: no pad


def test_padded_partial_speech_keeps_an_open_pause_silent(tts):
    s = SpeechStream(tts.sr)
    end = int(2.6 * tts.sr)  # inside the 1.2 s pause after "today?"
    for i in range(0, end, 320):
        s.feed(tts.audio[i : min(end, i + 320)])
    sp = s.speech(pad_s=1.0)
    assert sp.duration_s == pytest.approx(s.received_s + 1.0, abs=1e-3)
    assert sp.silent_spans[-1][1] == pytest.approx(sp.duration_s)  # the pause continues through the pad
    assert sp.n_frames == sp.features.mel_db.shape[0] == sp.features.pitch_hz.shape[0]
    # the pad is marked as not heard, also in a cut (the generator judges beats against the audio heard)
    assert sp.heard_s == pytest.approx(s.received_s)
    assert sp.crop(1.0).heard_s == pytest.approx(s.received_s - 1.0, abs=0.05)
    assert s.speech().heard_s is None  # nothing padded


def test_bad_chunks_are_refused_with_the_fix():
    s = SpeechStream(16000)
    with pytest.raises(InputError, match="mono"):
        s.feed(np.zeros((160, 2), np.int16))
    with pytest.raises(InputError, match="int16 or float32"):
        s.feed(np.zeros(160, np.int32))
    with pytest.raises(InputError, match="NaN"):
        s.feed(np.full(160, np.nan, np.float32))
    with pytest.raises(InputError, match=r"look-ahead"):
        SpeechStream(16000, lookahead_s=0.5)
    s.close()
    with pytest.raises(InputError, match="after close"):
        s.feed(np.zeros(160, np.int16))
