"""Spectral analysis of the speech front-end in numpy/scipy: no numba, so a first run compiles nothing.

librosa 0.11 compiles numba kernels on first use, and some (``guvectorize`` with signatures: local extrema,
parabolic interpolation, peak picking) already while its submodules are imported; with an empty numba cache
that took most of a first ``robogest speak`` (tens of seconds). The functions here follow the librosa calls
the front-end made, step for step and in the same dtypes (``scipy.fft`` as librosa's FFT library, float32
where librosa keeps float32), so results match librosa's to float rounding; ``tests/speech/test_nojit.py``
compares them on real speech. Only the defaults the front-end used are implemented (Hann window, zero
padding, Slaney mel scale and norm, ``power_to_db`` with ``ref=1``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: ``librosa.util.tiny`` of float32: keeps the envelope and YIN divisions finite.
_TINY32 = float(np.finfo(np.float32).tiny)


def frame(x: np.ndarray, frame_length: int, hop: int) -> np.ndarray:
    """Overlapping frames of the last axis, as a view: ndarray [shape=(..., n_frames, frame_length)].

    ``n_frames = 1 + (N - frame_length) // hop`` (``librosa.util.frame`` with the frame axis last).
    """
    if x.shape[-1] < frame_length:
        raise ValueError(f"signal of {x.shape[-1]} samples is shorter than one frame of {frame_length}")
    return sliding_window_view(x, frame_length, axis=-1)[..., ::hop, :]


def hann(n: int) -> np.ndarray:
    """Periodic Hann window, float64 [shape=(n,)]; computed as ``scipy.signal.get_window("hann", n)`` does
    (symmetric window of ``n + 1`` points, last dropped), so it is the same to the bit without scipy.signal."""
    fac = np.linspace(-np.pi, np.pi, n + 1)
    w = np.zeros(n + 1)
    w += 0.5 * np.cos(0 * fac)
    w += 0.5 * np.cos(fac)
    return w[:n]


def power_spectrogram(y: np.ndarray, n_fft: int, hop: int, center: bool = True) -> np.ndarray:
    """``|STFT|**2`` with a Hann window of ``n_fft`` samples (zero padding by ``n_fft // 2`` when centred).

    Parameters
    ----------
    y : ndarray [shape=(..., N)], float32

    Returns
    -------
    ndarray [shape=(..., 1 + n_fft // 2, T)], float32
    """
    import scipy.fft

    y = np.asarray(y, dtype=np.float32)
    if center:
        pad = [(0, 0)] * (y.ndim - 1) + [(n_fft // 2, n_fft // 2)]
        y = np.pad(y, pad)
    frames = frame(y, n_fft, hop)  # (..., T, n_fft); the float64 window makes the FFT float64, as in librosa
    spec = scipy.fft.rfft(frames * hann(n_fft), axis=-1).astype(np.complex64)
    power = np.abs(spec) ** 2
    return np.swapaxes(power, -1, -2)


#: Slaney mel scale (librosa's default): linear 200/3 Hz per mel below 1 kHz, logarithmic above.
_F_SP = 200.0 / 3
_MIN_LOG_HZ = 1000.0
_MIN_LOG_MEL = (_MIN_LOG_HZ - 0.0) / _F_SP
_LOGSTEP = np.log(6.4) / 27.0


def _hz_to_mel(f: float) -> float:
    if f >= _MIN_LOG_HZ:
        return float(_MIN_LOG_MEL + np.log(f / _MIN_LOG_HZ) / _LOGSTEP)
    return (f - 0.0) / _F_SP


def _mel_to_hz(m: np.ndarray) -> np.ndarray:
    freqs = 0.0 + _F_SP * m
    log_t = m >= _MIN_LOG_MEL
    freqs[log_t] = _MIN_LOG_HZ * np.exp(_LOGSTEP * (m[log_t] - _MIN_LOG_MEL))
    return freqs


def mel_filters(sr: int, n_fft: int, n_mels: int, fmax_hz: float | None = None) -> np.ndarray:
    """Triangular Slaney-normalised mel filters from 0 Hz to ``fmax_hz`` (``librosa.filters.mel`` defaults).

    Returns
    -------
    ndarray [shape=(n_mels, 1 + n_fft // 2)], float32
    """
    fmax = float(sr) / 2 if fmax_hz is None else float(fmax_hz)
    fftfreqs = np.fft.rfftfreq(n=n_fft, d=1.0 / sr)
    mel_f = _mel_to_hz(np.linspace(_hz_to_mel(0.0), _hz_to_mel(fmax), n_mels + 2))
    fdiff = np.diff(mel_f)
    ramps = np.subtract.outer(mel_f, fftfreqs)
    lower = -ramps[:-2] / fdiff[:-1, None]
    upper = ramps[2:] / fdiff[1:, None]
    weights: np.ndarray = np.maximum(0.0, np.minimum(lower, upper)).astype(np.float32)
    weights *= (2.0 / (mel_f[2 : n_mels + 2] - mel_f[:n_mels]))[:, None]
    return weights


def mel_power(y: np.ndarray, sr: int, n_fft: int, hop: int, n_mels: int, center: bool = True) -> np.ndarray:
    """Mel power spectrogram (``librosa.feature.melspectrogram``, power 2, window = FFT size).

    Returns
    -------
    ndarray [shape=(..., n_mels, T)], float32
    """
    s = power_spectrogram(y, n_fft, hop, center=center)
    mel: np.ndarray = np.einsum("...ft,mf->...mt", s, mel_filters(sr, n_fft, n_mels), optimize=True)
    return mel


def power_to_db(s: np.ndarray, amin: float = 1e-10, top_db: float | None = 80.0) -> np.ndarray:
    """``10 log10(max(amin, s))`` re 1.0, floored at ``max - top_db`` unless ``top_db`` is None."""
    log_spec: np.ndarray = 10.0 * np.log10(np.maximum(amin, s))
    log_spec -= 10.0 * np.log10(np.maximum(amin, 1.0))
    if top_db is not None:
        log_spec = np.maximum(log_spec, log_spec.max() - top_db)
    return log_spec


def mfcc_from_db(mel_db: np.ndarray, n_mfcc: int) -> np.ndarray:
    """Orthonormal DCT-II over the mel axis (``librosa.feature.mfcc(S=...)``).

    Parameters
    ----------
    mel_db : ndarray [shape=(T, n_mels)], dB

    Returns
    -------
    ndarray [shape=(T, n_mfcc)]
    """
    import scipy.fft

    coeffs: np.ndarray = scipy.fft.dct(mel_db, axis=-1, type=2, norm="ortho")[..., :n_mfcc]
    return coeffs


def yin(
    y: np.ndarray, sr: int, fmin_hz: float, fmax_hz: float, frame_length: int, hop: int, threshold: float = 0.1
) -> np.ndarray:
    """YIN f0 of centred, zero-padded frames (``librosa.yin`` with ``center=True, pad_mode="constant"``).

    Parameters
    ----------
    y : ndarray [shape=(N,)], float32

    Returns
    -------
    ndarray [shape=(1 + N // hop,)], Hz (never 0: unvoiced frames get the best period anyway)
    """
    y = np.pad(np.asarray(y, dtype=np.float32), (frame_length // 2, frame_length // 2))
    frames = frame(y, frame_length, hop).T  # (frame_length, T), lag axis first as in librosa
    min_period = int(np.floor(sr / fmax_hz))
    max_period = min(int(np.ceil(sr / fmin_hz)), frame_length - 1)
    d = _cmnd(frames, min_period, max_period)
    shifts = _parabolic_shifts(d)
    trough = np.zeros(d.shape, dtype=bool)  # local minima along the lag axis
    trough[1:-1] = (d[1:-1] < d[:-2]) & (d[1:-1] <= d[2:])
    trough[-1] = d[-1] < d[-2]
    trough[0] = d[0] < d[1]
    below = trough & (d < threshold)
    period = np.argmax(below, axis=0)[None, :]
    none = ~np.any(below, axis=0, keepdims=True)
    period[none] = np.argmin(d, axis=0)[None, :][none]
    period_s = (min_period + period + np.take_along_axis(shifts, period, axis=0))[0]
    pitch_hz: np.ndarray = sr / period_s
    return pitch_hz


def _cmnd(frames: np.ndarray, min_period: int, max_period: int) -> np.ndarray:
    """YIN's cumulative mean normalised difference, lags ``min_period..max_period``; [shape=(L, T)]."""
    import scipy.fft

    n_pad = scipy.fft.next_fast_len(2 * frames.shape[0] - 1, real=True)
    spec = scipy.fft.rfft(frames, n=n_pad, axis=0)
    acf = scipy.fft.irfft(spec.real**2 + spec.imag**2, n=n_pad, axis=0)[: max_period + 1]
    energy = np.cumsum(np.square(frames), axis=0)
    energy[0] = 0  # librosa zeroes this row before using it as the k = 1 energy term; kept for equal results
    diff = np.empty_like(energy)
    diff[0] = 0
    diff[1 : max_period + 1] = 2 * (acf[0:1] - acf[1 : max_period + 1]) - energy[:max_period]
    lags = np.arange(1, max_period + 1)[:, None]
    mean = np.cumsum(diff[1 : max_period + 1], axis=0) / lags
    den = mean[min_period - 1 : max_period]
    return diff[min_period : max_period + 1] / (den + float(np.finfo(den.dtype).tiny))


def _parabolic_shifts(d: np.ndarray) -> np.ndarray:
    """Vertex offset of the parabola through each bin and its neighbours (0 at the ends or beyond +-1 bin).

    Rounds as librosa's numba stencil does: neighbour sums in the input dtype, the rest in float64.
    """
    out = np.zeros_like(d)
    s = (d[2:] + d[:-2]).astype(np.float64)
    a = s - 2.0 * d[1:-1].astype(np.float64)
    b = (d[2:] - d[:-2]).astype(np.float64) / 2.0
    ok = np.abs(b) < np.abs(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[1:-1] = np.where(ok, -b / np.where(ok, a, 1.0), 0.0)
    return out


def onset_strength(y: np.ndarray, sr: int, hop: int, n_fft: int, n_mels: int) -> np.ndarray:
    """Spectral flux of the log-mel spectrogram (``librosa.onset.onset_strength``, lag 1, no max filter).

    Returns
    -------
    ndarray [shape=(1 + N // hop,)], float32; frame ``i`` at ``i * hop / sr`` s
    """
    s = power_to_db(np.abs(mel_power(y, sr, n_fft, hop, n_mels)))
    env = np.maximum(0.0, s[:, 1:] - s[:, :-1])
    env = np.mean(env, axis=0, keepdims=True)
    env = np.pad(env, [(0, 0), (1 + n_fft // (2 * hop), 0)])
    return env[0, : s.shape[-1]]


def onset_detect(env: np.ndarray, sr: int, hop: int, normalize: bool = True) -> np.ndarray:
    """Onset frames: peaks of the envelope with librosa's defaults (``librosa.onset.onset_detect``).

    A frame is a peak when it is the maximum of the 30 ms before it and itself, at least 0.07 above the mean
    of the 100 ms around it, and 30 ms after the previous peak.

    Returns
    -------
    ndarray [shape=(K,)], int frame indices
    """
    if normalize:
        env = env - np.min(env)
        env = env / (np.max(env) + _TINY32)
    if not env.any() or not np.all(np.isfinite(env)):
        return np.zeros(0, dtype=int)
    pre_max, post_max = math.ceil(0.03 * sr // hop), math.ceil(0.00 * sr // hop + 1)
    pre_avg, post_avg = math.ceil(0.10 * sr // hop), math.ceil(0.10 * sr // hop + 1)
    wait = math.ceil(0.03 * sr // hop)
    return peak_pick(env, pre_max, post_max, pre_avg, post_avg, float(np.float32(0.07)), wait)


def peak_pick(
    x: np.ndarray, pre_max: int, post_max: int, pre_avg: int, post_avg: int, delta: float, wait: int
) -> np.ndarray:
    """``librosa.util.peak_pick`` without numba; ndarray [shape=(K,)] of int indices into ``x`` [shape=(N,)].

    Both tests run vectorised, the mean as librosa's kernel adds it (a running sum in the dtype of ``x``,
    divided in float64); only the ``wait`` rule loops, over the frames that passed both.
    """
    n = x.shape[0]
    pad = np.pad(x, (pre_max, post_max), constant_values=-np.inf)
    win_max = sliding_window_view(pad, pre_max + post_max)[:n].max(axis=1)  # max of x[i - pre_max : i + post_max]
    cand = np.flatnonzero(x == win_max)
    lo, hi = np.maximum(0, cand - pre_avg), np.minimum(n, cand + post_avg)
    idx = lo[:, None] + np.arange(pre_avg + post_avg)[None, :]
    vals = np.where(idx < hi[:, None], x[np.minimum(idx, n - 1)], 0)  # trailing zeros leave the running sum as is
    mean = np.cumsum(vals, axis=1)[:, -1].astype(np.float64) / (hi - lo)
    peaks: list[int] = []
    nxt = 0
    for i in cand[x[cand] >= mean + delta].tolist():
        if i >= nxt:
            peaks.append(i)
            nxt = i + wait + 1
    return np.asarray(peaks, dtype=int)


def resample(y: np.ndarray, sr_in: int, sr_out: int) -> np.ndarray:
    """soxr high-quality resampling trimmed or padded to ``ceil(N * sr_out / sr_in)`` (``librosa.resample``)."""
    import soxr

    out = soxr.resample(y, sr_in, sr_out, quality="soxr_hq")
    n = math.ceil(y.shape[0] * (float(sr_out) / sr_in))
    return np.pad(out, (0, max(0, n - out.shape[0])))[:n]
