"""Writing a :class:`Speech` out: features archive, WAV for the video muxer, summary for the CLI."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path, write_error
from robogest.speech.types import Speech


def _atomic_write(path: str | Path, write: Callable[[IO[bytes]], None]) -> Path:
    """Write via a temporary file in the target folder, then ``os.replace`` it into place."""
    p = Path(path)
    if not p.parent.is_dir():
        raise InputError(f"{p}: output folder {p.parent} does not exist")
    try:
        with atomic_path(p) as tmp, open(tmp, "wb") as f:
            write(f)
    except AssertionError:  # libsndfile's short write (disk full) reaches soundfile as an assertion
        raise write_error(p, OSError("short write: the disk may be full")) from None
    except OSError as e:
        raise write_error(p, e) from None
    return p


def feature_arrays(speech: Speech) -> dict[str, np.ndarray]:
    """Every array of ``speech`` except the audio, under the keys :func:`save_features` uses.

    ``silent_spans`` is ndarray [shape=(S, 2)], seconds; ``word_text`` a unicode array; no object arrays,
    so ``np.load(path)`` works without ``allow_pickle``.
    """
    f = speech.features
    words = speech.words
    return {
        "fps": np.float64(f.fps),
        "sr": np.int64(speech.sr),
        "duration_s": np.float64(speech.duration_s),
        "n_frames": np.int64(f.n_frames),
        "mel_db": f.mel_db,
        "mfcc": f.mfcc,
        "rms": f.rms,
        "pitch_hz": f.pitch_hz,
        "word_features": f.word_features,
        "filler": f.filler,
        "silence": f.silence,
        "beats_s": speech.beats_s,
        "beat_is_pseudo": speech.beat_is_pseudo,
        "silent_spans": np.asarray(speech.silent_spans, dtype=np.float64).reshape(-1, 2),
        "noise_level": np.float64(speech.noise_level),
        "word_text": np.asarray([w.text for w in words], dtype=str),
        "word_start_s": np.asarray([w.start_s for w in words], dtype=np.float64),
        "word_end_s": np.asarray([w.end_s for w in words], dtype=np.float64),
        "word_syllables": np.asarray([w.syllables for w in words], dtype=np.int64),
        "source": np.asarray(speech.source, dtype=str),
        "text": np.asarray(speech.text, dtype=str),
    }


def save_features(speech: Speech, path: str | Path) -> Path:
    """Save every feature array, beats, silent spans and words to a compressed ``.npz`` (atomic write).

    Keys are those of :func:`feature_arrays`. Returns the path written.
    """
    arrays = feature_arrays(speech)
    return _atomic_write(path, lambda f: np.savez_compressed(f, allow_pickle=False, **arrays))


def write_wav(speech: Speech, path: str | Path) -> Path:
    """Write the (mono, ``speech.sr``) audio as 16-bit PCM WAV, atomically; returns the path."""
    import soundfile as sf

    audio = np.clip(speech.audio, -1.0, 1.0)
    p = Path(path)
    if not p.parent.is_dir():
        raise InputError(f"{p}: output folder {p.parent} does not exist")
    try:  # by name: libsndfile's own writes; through a Python file object a full disk printed tracebacks from its
        with atomic_path(p, ".wav") as tmp:  # I/O callbacks, which Python can only report as "Exception ignored"
            sf.write(str(tmp), audio, speech.sr, format="WAV", subtype="PCM_16")
    except (AssertionError, RuntimeError):  # a short write (disk full) or libsndfile's error
        raise write_error(p, OSError("libsndfile could not write it; the disk may be full")) from None
    return p


def speech_summary(speech: Speech) -> dict[str, Any]:
    """Plain-Python (JSON-ready) summary for ``robogest analyze``.

    Keys: ``source``, ``duration_s``, ``sr``, ``fps``, ``n_frames``, ``n_words``, ``n_fillers``,
    ``n_beats``, ``n_pseudo_beats``, ``beats_per_s_speech`` (onset beats per second outside silent spans),
    ``silent_spans`` (list of [start_s, end_s]), ``silent_s``, ``noise_level`` (linear RMS),
    ``noise_level_db`` (dBFS), ``speaking_rate_syll_s`` (syllables per second of word time, 0 without
    words), ``voiced_fraction`` (share of frames with a pitch), ``median_pitch_hz`` (0 if none voiced).
    """
    f = speech.features
    silent_s = float(sum(b - a for a, b in speech.silent_spans))
    speech_s = max(speech.duration_s - silent_s, 0.0)
    word_s = sum(w.end_s - w.start_s for w in speech.words)
    voiced = f.pitch_hz[f.pitch_hz > 0]
    n_real = int(np.count_nonzero(~speech.beat_is_pseudo))
    return {
        "source": speech.source,
        "duration_s": round(speech.duration_s, 3),
        "sr": int(speech.sr),
        "fps": float(f.fps),
        "n_frames": int(f.n_frames),
        "n_words": len(speech.words),
        "n_fillers": sum(w.is_filler for w in speech.words),
        "n_beats": int(speech.beats_s.shape[0]),
        "n_pseudo_beats": int(np.count_nonzero(speech.beat_is_pseudo)),
        "beats_per_s_speech": round(n_real / speech_s, 3) if speech_s > 0 else 0.0,
        "silent_spans": [[round(a, 3), round(b, 3)] for a, b in speech.silent_spans],
        "silent_s": round(silent_s, 3),
        "noise_level": float(speech.noise_level),
        "noise_level_db": round(float(20.0 * np.log10(max(speech.noise_level, 1e-12))), 1),
        "speaking_rate_syll_s": round(sum(w.syllables for w in speech.words) / word_s, 3) if word_s > 0 else 0.0,
        "voiced_fraction": round(float(voiced.shape[0] / max(f.n_frames, 1)), 3),
        "median_pitch_hz": round(float(np.median(voiced)), 1) if voiced.size else 0.0,
    }
