"""Reading audio files into mono float32 at the analysis rate."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from robogest.errors import InputError

#: Sample rates accepted, Hz: telephone speech to studio recordings; anything else is a broken header.
SAMPLE_RATE_RANGE_HZ = (4000, 384000)


def _check_rate(p: Path, sr: int) -> None:
    lo, hi = SAMPLE_RATE_RANGE_HZ
    if not lo <= sr <= hi:
        raise InputError(f"audio {p}: sample rate {sr} Hz is outside {lo}..{hi} Hz; the header is broken, re-export it")


def to_mono(audio: np.ndarray) -> np.ndarray:
    """Mix down to mono.

    Parameters
    ----------
    audio : ndarray [shape=(N,) or (N, C)], float
        Samples, channels last (soundfile's layout).

    Returns
    -------
    ndarray [shape=(N,)], float32
        Channel mean.
    """
    a = np.asarray(audio, dtype=np.float32)
    if a.ndim == 2:
        a = a.mean(axis=1, dtype=np.float32) if a.shape[1] > 1 else a[:, 0]
    if a.ndim != 1:
        raise ValueError(f"expected audio of shape (N,) or (N, C), got {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def resample(audio: np.ndarray, sr_in: int, sr_out: int) -> np.ndarray:
    """Resample mono float32 audio (soxr high quality, as librosa.resample; no librosa import); identity when
    rates match.

    Returns
    -------
    ndarray [shape=(ceil(N * sr_out / sr_in),)], float32
    """
    if int(sr_in) == int(sr_out):
        return np.ascontiguousarray(audio, dtype=np.float32)
    from robogest.speech import dsp

    y = np.asarray(audio, dtype=np.float32)
    return np.ascontiguousarray(dsp.resample(y, int(sr_in), int(sr_out)), dtype=np.float32)


def read_audio(path: str | Path, max_duration_s: float) -> tuple[np.ndarray, int]:
    """Read WAV/FLAC/OGG/MP3 (anything libsndfile opens, else librosa/audioread) as mono float32.

    Parameters
    ----------
    path : str or Path
        Audio file.
    max_duration_s : float
        Longer files are rejected before they are decoded in full.

    Returns
    -------
    audio : ndarray [shape=(N,)], float32
        Mono samples at the file's own rate (stereo is averaged).
    sr : int
        The file's sample rate, Hz.

    Raises
    ------
    InputError
        Missing or unreadable file, no samples, too long, or non-finite samples.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"audio {p}: file not found")
    if not p.is_file():
        raise InputError(f"audio {p}: not a file")
    import soundfile as sf

    try:
        info = sf.info(str(p))
        _check_rate(p, info.samplerate)
        if info.samplerate > 0 and info.frames / info.samplerate > max_duration_s:
            raise InputError(
                f"audio {p}: {info.frames / info.samplerate:.1f} s is longer than the maximum "
                f"{max_duration_s:.1f} s; cut it or raise max_duration_s"
            )
        data, sr = sf.read(str(p), dtype="float32", always_2d=True)
    except InputError:
        raise
    except Exception as sf_exc:  # libsndfile cannot open it (e.g. MP3 on old builds): try audioread
        data, sr = _read_fallback(p, sf_exc)
    if data.size == 0:
        raise InputError(f"audio {p}: contains no samples")
    _check_rate(p, int(sr))
    audio = to_mono(data)
    if audio.shape[0] / sr > max_duration_s:
        raise InputError(
            f"audio {p}: {audio.shape[0] / sr:.1f} s is longer than the maximum {max_duration_s:.1f} s; "
            "cut it or raise max_duration_s"
        )
    if not np.all(np.isfinite(audio)):
        raise InputError(f"audio {p}: contains NaN or infinite samples")
    return audio, int(sr)


def _read_fallback(p: Path, first_error: Exception) -> tuple[np.ndarray, int]:
    try:
        import librosa

        with warnings.catch_warnings():  # librosa warns that audioread is deprecated; the error below says enough
            warnings.simplefilter("ignore")
            y, sr = librosa.load(str(p), sr=None, mono=False)
    except Exception as exc:
        raise InputError(f"audio {p}: cannot decode as audio ({first_error}; fallback: {exc})") from exc
    y = np.asarray(y, dtype=np.float32)
    return (y.T if y.ndim == 2 else y[:, None]), int(sr)
