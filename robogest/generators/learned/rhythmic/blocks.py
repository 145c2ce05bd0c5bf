"""Rhythm-based segmentation and normalisation (Rhythmic Gesticulator §4.2): clips between beats <-> uniform blocks.

Speech and motion are cut at every beat into clips of ``n`` frames (``D_m <= n / fps <= D_M`` for real beats) and
every clip is time-scaled to a block of ``K = D_M * fps`` frames. Resampling is linear with the clip's first and
last frames mapped onto the block's first and last frames (endpoint-aligned), so

* a linear trajectory round-trips exactly and neighbouring clips stay continuous after denormalisation;
* denormalising gives back exactly ``sum(n)`` frames, i.e. the input's duration to the frame.

Audio is time-scaled on the waveform with librosa's phase vocoder followed by a fresh mel analysis
(:func:`tsm_mel_blocks`, the paper's TSM route), or, for frame arrays without their audio, in the feature domain
(:func:`normalize_clips` on the log-mel frames: only the time axis is rescaled, so the mel band of every partial is
kept). Numpy + librosa only; no torch here.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from robogest.errors import InputError
from robogest.speech.beats import identify_beats


def block_frames(max_gap_s: float, fps: float) -> int:
    """Block length ``K = round(D_M * fps)`` frames (10 at 0.5 s and 20 fps)."""
    k = round(max_gap_s * fps)
    if k < 2:
        raise InputError(f"a block of D_M = {max_gap_s} s at {fps} fps has fewer than 2 frames")
    return int(k)


def clip_bounds(beats_s: np.ndarray, n_frames: int, fps: float) -> np.ndarray:
    """Frame boundaries of the clips between consecutive beats.

    Parameters
    ----------
    beats_s : ndarray [shape=(B,)], seconds
        Beat times (any order; those outside ``(0, n_frames / fps)`` are ignored).
    n_frames : int
    fps : float

    Returns
    -------
    ndarray [shape=(C + 1,)], int
        ``0 = b_0 < b_1 < ... < b_C = n_frames``; clip ``c`` is frames ``[b_c, b_{c+1})``. Beats that round to
        the same frame are merged, so every clip has at least one frame.
    """
    if n_frames <= 0:
        return np.zeros(1, dtype=int)
    inner = np.rint(np.asarray(beats_s, dtype=np.float64) * fps).astype(int)
    inner = np.unique(inner[(inner > 0) & (inner < n_frames)])
    return np.concatenate([[0], inner, [n_frames]]).astype(int)


def _positions(n: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Endpoint-aligned linear interpolation of ``n`` samples at ``k`` points: ``(i0, i1, w)``, each ``(k,)``."""
    pos = np.zeros(k) if n == 1 else np.linspace(0.0, n - 1.0, k)  # fractional source index
    i0 = np.minimum(np.floor(pos).astype(int), n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    return i0, i1, pos - i0


def resample_clip(x: np.ndarray, k: int) -> np.ndarray:
    """Time-scale ``x`` ``(n, D)`` to ``(k, D)`` (endpoint-aligned linear interpolation)."""
    i0, i1, w = _positions(x.shape[0], k)
    out: np.ndarray = ((1.0 - w)[:, None] * x[i0] + w[:, None] * x[i1]).astype(x.dtype, copy=False)
    return out


def normalize_clips(x: np.ndarray, bounds: np.ndarray, k: int) -> np.ndarray:
    """Frames ``x`` ``(T, D)`` -> blocks ``(C, k, D)``, one per clip of ``bounds`` (:func:`resample_clip` each)."""
    blocks = [resample_clip(x[a:b], k) for a, b in itertools.pairwise(np.asarray(bounds, dtype=int))]
    if not blocks:
        return np.zeros((0, k, x.shape[1]), np.float32)
    return np.stack(blocks).astype(np.float32)  # (C, k, D)


def denormalize_blocks(blocks: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Blocks ``(C, k, D)`` -> frames ``(sum(lengths), D)``: block ``c`` is time-scaled back to ``lengths[c]``."""
    lengths = np.asarray(lengths, dtype=int)
    if blocks.shape[0] != lengths.shape[0]:
        raise InputError(f"{blocks.shape[0]} blocks but {lengths.shape[0]} clip lengths")
    if blocks.shape[0] == 0:
        return np.zeros((0, blocks.shape[2]), np.float32)
    return np.concatenate([resample_clip(b, int(n)) for b, n in zip(blocks, lengths, strict=True)]).astype(np.float32)


def block_fraction(mask: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Share of each clip's frames where the boolean frame ``mask`` ``(T,)`` is set; ``(C,)``."""
    c = np.concatenate([[0], np.cumsum(np.asarray(mask, dtype=np.float64))])
    share: np.ndarray = (c[bounds[1:]] - c[bounds[:-1]]) / np.maximum(bounds[1:] - bounds[:-1], 1)
    return share


def mel_volume(mel: np.ndarray) -> tuple[np.ndarray, float]:
    """Loudness track and noise level of standardised log-mel frames for the beat rule (:func:`frame_beats`).

    Loudness is the band-averaged log-mel ``(T,)``; the noise level is its 20th percentile plus half a unit. Both
    assume per-band standardised log-mel (:class:`~robogest.data.prep.Normalization`), where one unit is one
    standard deviation. A frame is loud when its loudness exceeds the noise level.
    """
    volume = mel.mean(axis=1) if mel.shape[0] else np.zeros(0)
    noise = float(np.percentile(volume, 20)) + 0.5 if volume.size else 0.0
    return volume, noise


def quiet_frames(
    mel_db: np.ndarray, noise_percentile: float = 10.0, margin_db: float = 12.0, floor_db: float = -80.0
) -> np.ndarray:
    """Quiet frames ``(T,)`` bool of a raw log-mel (dB) sequence: the frame-domain analogue of the speech
    front-end's silence rule (:mod:`robogest.speech.silence`), for takes that only keep their features.

    The frame's mel power (band mean, dB) is compared with the noise level, its ``noise_percentile``-th
    percentile (at least ``floor_db``), plus the front-end's ``speech_margin_db`` (12 dB): at or below it the frame
    is quiet. Unlike the front-end there is no minimum span length; :func:`silent_blocks` asks for a majority of
    quiet frames per block instead.
    """
    if mel_db.shape[0] == 0:
        return np.zeros(0, bool)
    power = 10.0 * np.log10(np.mean(10.0 ** (np.asarray(mel_db, np.float64) / 10.0), axis=1) + 1e-20)  # (T,) dB
    noise = max(float(np.percentile(power, noise_percentile)), floor_db)
    quiet: np.ndarray = power <= noise + margin_db
    return quiet


def silent_blocks(bounds: np.ndarray, words: np.ndarray, quiet: np.ndarray, quiet_share: float = 0.5) -> np.ndarray:
    """Silent clips ``(C,)`` bool (the silent-period hint of §6.4.1, also without a transcript).

    A clip is silent when it overlaps no word and, only when the whole sequence has no words at all (audio
    without transcript, where "no word" says nothing), when its quiet frames are more than ``quiet_share`` of it.

    Parameters
    ----------
    bounds : ndarray [shape=(C + 1,)], int
    words : ndarray [shape=(T,)], bool
        Frames inside a word.
    quiet : ndarray [shape=(T,)], bool
        :func:`quiet_frames`.
    """
    no_word: np.ndarray = block_fraction(words, bounds) == 0.0
    if np.any(words):
        return no_word
    silent: np.ndarray = no_word & (block_fraction(quiet, bounds) > quiet_share)
    return silent


def frame_beats(
    mel: np.ndarray, fps: float, min_gap_s: float = 0.2, max_gap_s: float = 0.5, onset_threshold: float = 0.5
) -> np.ndarray:
    """Beats of a log-mel sequence by the §4.2.1 rule, for frame arrays without their audio.

    Onsets are local maxima of the band-averaged positive spectral flux above ``onset_threshold``; loudness and
    noise level come from :func:`mel_volume`. :func:`~robogest.speech.beats.identify_beats` then applies D_m /
    D_M and the pseudo-beats. The learned Rhythmic Gesticulator cuts both its training takes and its run-time
    speech with this function on the same standardised log-mel, so training and inference blocks follow one rule.

    Parameters
    ----------
    mel : ndarray [shape=(T, M)]
        Standardised log-mel frames.
    fps : float

    Returns
    -------
    ndarray [shape=(B,)], seconds
    """
    t = mel.shape[0]
    if t == 0:
        return np.zeros(0)
    flux = np.zeros(t)
    if t > 1:
        flux[1:] = np.maximum(np.diff(mel, axis=0), 0.0).mean(axis=1)  # (T,)
    prev, nxt = np.r_[-np.inf, flux[:-1]], np.r_[flux[1:], -np.inf]
    onsets = np.flatnonzero((flux >= prev) & (flux > nxt) & (flux > onset_threshold)) / fps
    volume, noise = mel_volume(mel)
    beats, _ = identify_beats(onsets, volume, noise, fps, min_gap_s, max_gap_s, duration_s=t / fps)
    return beats


def gaussian_smooth(x: np.ndarray, kernel: int = 5, sigma: float | None = None) -> np.ndarray:
    """Gaussian smoothing along time (axis 0) with edge padding, so the length is kept.

    Parameters
    ----------
    x : ndarray [shape=(T, D)]
    kernel : int
        Odd kernel size in frames (5 at run time, §6); 1 returns ``x``.
    sigma : float, optional
        Standard deviation in frames; ``kernel / 4`` by default (the kernel spans ±2 σ).
    """
    if kernel <= 1 or x.shape[0] == 0:
        return x
    if kernel % 2 == 0:
        raise InputError(f"smoothing kernel must be odd, got {kernel}")
    s = kernel / 4.0 if sigma is None else sigma
    h = kernel // 2
    g = np.exp(-0.5 * (np.arange(-h, h + 1) / s) ** 2)
    g /= g.sum()
    padded = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])  # (T + 2h, D)
    out = np.zeros_like(x, dtype=np.float64)
    for j, gj in enumerate(g):
        out += gj * padded[j : j + x.shape[0]]
    return out.astype(x.dtype, copy=False)


def tsm_mel_blocks(
    audio: np.ndarray, sr: int, bounds: np.ndarray, fps: float, k: int, n_mels: int = 64, window_s: float = 0.1
) -> np.ndarray:
    """Mel blocks of pitch-preserving time-scaled audio, features recomputed (the paper's TSM route, §4.2.2).

    Clip ``[a, b)`` (frames) is stretched with librosa's phase vocoder at the constant rate ``r = (n - 1) / (k - 1)``
    source frames per block frame, so block frame ``j`` is centred where the motion block's frame ``j`` samples the
    clip (:func:`normalize_clips` is endpoint-aligned: source frame ``a + j r``). The clip is stretched together
    with half a mel window (plus the vocoder's own window) of the audio on each side, so the block's edge frames
    see real audio as the front-end's frames do, and the log-mel is recomputed on the stretched signal with the
    front-end's analysis (:func:`robogest.speech.features.log_mel_db`: ``window_s`` window, hop ``sr / fps``).
    A clip of ``k`` frames (``r = 1``) therefore reproduces the front-end's own frames.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
        The take's samples; frame ``t`` is centred at sample ``t * hop``.
    sr : int
        Hz.
    bounds : ndarray [shape=(C + 1,)], int
        Clip boundaries in frames at ``fps`` (:func:`clip_bounds`).

    Returns
    -------
    ndarray [shape=(C, k, n_mels)], dB re 1.0
    """
    import librosa

    from robogest.speech.features import log_mel_db, mel_hop_win

    hop, win = mel_hop_win(sr, fps, window_s)
    n_fft = 1 << max(6, round(math.log2(0.032 * sr)))  # vocoder STFT: 32 ms (512 at 16 kHz), hop a quarter
    audio = np.asarray(audio, np.float32)
    bounds = np.asarray(bounds, dtype=int)
    lengths = np.diff(bounds)
    out = np.zeros((lengths.shape[0], k, n_mels), np.float32)
    for n in np.unique(lengths):  # one vocoder call per clip length (= rate) on the stack of those clips
        which = np.flatnonzero(lengths == n)
        r = max(max(int(n) - 1, 0) / (k - 1), 0.1)  # one-frame clips: a slow stretch of the frame's neighbourhood
        margin = math.ceil(r * win / 2) + n_fft  # source samples kept on each side
        span = (int(n) - 1) * hop + 2 * margin
        segs = np.zeros((which.shape[0], span), np.float32)  # zero outside the audio, like the front-end's padding
        for row, c in enumerate(which):
            lo = int(bounds[c]) * hop - margin
            s0, s1 = max(lo, 0), min(lo + span, audio.shape[0])
            if s1 > s0:
                segs[row, s0 - lo : s1 - lo] = audio[s0:s1]
        stretched = librosa.effects.time_stretch(segs, rate=r, n_fft=n_fft, hop_length=n_fft // 4)  # (m, ~span / r)
        first = round(margin / r - win / 2)  # start of block frame 0's window in the stretched signal
        piece = librosa.util.fix_length(stretched[:, first:], size=(k - 1) * hop + win, axis=-1)
        out[which] = log_mel_db(piece, sr, hop, win, n_mels, center=False)[:, :k]  # (m, k, n_mels)
    return out
