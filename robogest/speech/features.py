"""Frame-synchronous acoustic and word features.

Frame ``t`` is centred at ``t / fps`` s and there are ``T = ceil(duration * fps)`` frames, so the
frames cover ``[0, duration)`` and a motion of ``T`` frames lasts as long as the speech. Spectral frames
are centred (zero padding at both ends). When ``sr / fps`` is not a whole number of samples the
features are computed at the nearest smaller integer hop and interpolated onto the exact frame times
(linear for continuous features, nearest for pitch), so long files do not drift.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from robogest.speech import dsp
from robogest.speech.config import SpeechConfig
from robogest.speech.silence import frame_rms
from robogest.speech.types import SpeechFeatures, Word

#: Columns of :attr:`SpeechFeatures.word_features` (Gesticulator Table 1, without the BERT vector).
WORD_FEATURE_NAMES = ("time_since_start_s", "time_to_end_s", "duration_s", "progress", "rate_syll_s")

#: Cepstral coefficients kept. S2AG §3.1.1 says "14 MFCCs ... 13 coefficients ... first- and second-order
#: differences of the 13 coefficients ... a total of 37", which does not add up (14 + 13 + 13 = 40). The
#: (T, 37) contract is kept with the classic layout c0 (log energy), c1..c12, then forward differences and
#: second forward differences of c1..c12: 13 + 12 + 12 = 37 columns.
N_MFCC = 13


def _frame_positions(n_frames: int, fps: float, sr: int, hop: int) -> np.ndarray | None:
    """Fractional source-frame index of each target frame, or None when the hop is exact."""
    if math.isclose(sr / fps, hop, rel_tol=0.0, abs_tol=1e-9):
        return None
    return np.arange(n_frames) * (sr / fps) / hop


def _take(x: np.ndarray, n_frames: int, pos: np.ndarray | None, nearest: bool = False) -> np.ndarray:
    """Rows of ``x`` (time first) at the target frames; pads by edge repetition if short."""
    if pos is None:
        idx = np.minimum(np.arange(n_frames), x.shape[0] - 1)
        rows: np.ndarray = x[idx]
        return rows
    if nearest:
        nearest_rows: np.ndarray = x[np.clip(np.rint(pos).astype(int), 0, x.shape[0] - 1)]
        return nearest_rows
    i0 = np.clip(np.floor(pos).astype(int), 0, x.shape[0] - 1)
    i1 = np.minimum(i0 + 1, x.shape[0] - 1)
    w = (pos - np.floor(pos)).astype(np.float32)
    if x.ndim == 2:
        w = w[:, None]
    blended: np.ndarray = (1.0 - w) * x[i0] + w * x[i1]
    return blended


def forward_diff(x: np.ndarray) -> np.ndarray:
    """Forward difference along time, ``d[t] = x[t+1] - x[t]``, last row 0 (S2AG §3.1.1).

    Parameters
    ----------
    x : ndarray [shape=(T, D)]

    Returns
    -------
    ndarray [shape=(T, D)]
    """
    d = np.zeros_like(x)
    if x.shape[0] > 1:
        d[:-1] = x[1:] - x[:-1]
    return d


def acoustic_features(
    audio: np.ndarray, sr: int, config: SpeechConfig, activity_threshold: float, spectral: bool = True
) -> dict:
    """Mel spectrogram, MFCC, RMS and pitch on the frame grid.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
        Mono samples at ``sr``.
    sr : int
        Sample rate, Hz.
    config : SpeechConfig
    activity_threshold : float
        RMS (linear) a frame must exceed to be voiced, see :mod:`robogest.speech.silence`.
    spectral : bool
        Compute mel and MFCC (False leaves them zero: the streaming front-end serves only generators that
        use RMS and pitch, and saves their cost on every update).

    Returns
    -------
    dict
        ``mel_db`` : ndarray [shape=(T, n_mels)], dB re 1.0, floor -100 dB;
        ``mfcc`` : ndarray [shape=(T, 37)], see :data:`N_MFCC` for the layout (MFCC taken from the same
        64-band log-mel spectrum);
        ``rms`` : ndarray [shape=(T,)], linear amplitude over the mel window;
        ``pitch_hz`` : ndarray [shape=(T,)], Hz, 0 where unvoiced.
    """
    n_frames = config.n_frames(audio.shape[0], sr)
    hop, win = mel_hop_win(sr, config.fps, config.mel_window_s)
    pos = _frame_positions(n_frames, config.fps, sr, hop)
    if n_frames == 0:
        z = np.zeros((0,), np.float32)
        return {"mel_db": np.zeros((0, config.n_mels), np.float32), "mfcc": np.zeros((0, 37), np.float32),
                "rms": z, "pitch_hz": z.copy()}  # fmt: skip

    rms = frame_rms(audio, sr, hop, win)
    if spectral:
        mel_db = log_mel_db(audio, sr, hop, win, config.n_mels)
        cep = dsp.mfcc_from_db(mel_db, N_MFCC).astype(np.float32)
    else:
        mel_db = np.zeros((rms.shape[0], config.n_mels), np.float32)
        cep = np.zeros((rms.shape[0], N_MFCC), np.float32)

    frame_length = 1 << math.ceil(math.log2(4.0 * sr / config.fmin_hz))
    if audio.shape[0] >= 1:
        f0 = dsp.yin(audio, sr, config.fmin_hz, config.fmax_hz, frame_length, hop)
        harm = harmonicity(audio, sr, f0, frame_length, hop, config.fmax_hz, config.fmin_hz)
    else:  # pragma: no cover - guarded by the caller
        f0 = harm = np.zeros(1)
    m = min(mel_db.shape[0], rms.shape[0], f0.shape[0])
    voiced = (harm[:m] >= config.voicing_harmonicity) & (rms[:m] > activity_threshold)
    pitch = np.where(voiced, f0[:m], 0.0).astype(np.float32)
    return {
        "mel_db": _take(mel_db[:m], n_frames, pos).astype(np.float32),
        "mfcc": _with_differences(_take(cep[:m], n_frames, pos)).astype(np.float32),
        "rms": _take(rms[:m], n_frames, pos).astype(np.float32),
        "pitch_hz": _take(pitch, n_frames, pos, nearest=True).astype(np.float32),
    }


def mel_hop_win(sr: int, fps: float, window_s: float) -> tuple[int, int]:
    """Hop and window of the front-end's spectral frames, samples: the largest whole hop not above ``sr / fps``
    (frames are interpolated onto the exact frame times when it is not whole) and ``window_s`` rounded."""
    return max(1, math.floor(sr / fps + 1e-9)), max(16, round(window_s * sr))


def log_mel_db(audio: np.ndarray, sr: int, hop: int, win: int, n_mels: int, center: bool = True) -> np.ndarray:
    """The front-end's log-power mel spectrogram; one function so time-scaled audio is analysed identically.

    Parameters
    ----------
    audio : ndarray [shape=(..., N)], float32
        One signal, or a stack of equally long ones.
    sr, hop, win : int
        Hz, samples, samples (the FFT size is the window).
    center : bool
        Frame ``t`` centred at sample ``t * hop`` with zero padding (True) or starting there (False).

    Returns
    -------
    ndarray [shape=(..., T, n_mels)], dB re 1.0, floor -100 dB
    """
    mel = dsp.mel_power(audio, sr, win, hop, n_mels, center=center)  # numpy/scipy: nothing to JIT-compile
    db = dsp.power_to_db(mel, amin=1e-10, top_db=None)  # (..., n_mels, T)
    return np.swapaxes(db, -1, -2).astype(np.float32)  # (..., T, n_mels)


def _with_differences(cep: np.ndarray) -> np.ndarray:
    """[c0..c12 | forward diff of c1..c12 | its forward diff], on the output frame grid; [shape=(T, 37)]."""
    d1 = forward_diff(cep[:, 1:])
    return np.concatenate([cep, d1, forward_diff(d1)], axis=1)


def harmonicity(
    audio: np.ndarray, sr: int, f0: np.ndarray, frame_length: int, hop: int, fmax_hz: float, fmin_hz: float
) -> np.ndarray:
    """Normalised autocorrelation of each centred frame at the YIN period: ~1 periodic, ~0 noise.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
    f0 : ndarray [shape=(F,)], Hz
        YIN estimate per frame.

    Returns
    -------
    ndarray [shape=(F,)], in [-1, 1]
    """
    pad = frame_length // 2
    y = np.pad(audio.astype(np.float32), (pad, pad + frame_length))
    frames = dsp.frame(y, frame_length, hop)[: f0.shape[0]]
    lag = np.clip(np.rint(sr / np.maximum(f0[: frames.shape[0]], 1e-3)), math.floor(sr / fmax_hz), sr / fmin_hz)
    lag = lag.astype(int)
    width = frame_length - int(lag.max(initial=1))
    a = frames[:, :width]
    b = frames[np.arange(frames.shape[0])[:, None], lag[:, None] + np.arange(width)[None, :]]
    num = np.einsum("ij,ij->i", a, b)
    den = np.sqrt(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b)) + 1e-12
    out = np.zeros(f0.shape[0], np.float32)
    out[: frames.shape[0]] = num / den
    return out


def word_features(words: Sequence[Word], n_frames: int, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Gesticulator Table 1 scalars per frame, and the filler mask.

    A frame at ``tau = t / fps`` belongs to word ``w`` when ``w.start_s <= tau < w.end_s``.

    Returns
    -------
    feats : ndarray [shape=(T, 5)], float32
        Time since word start (s), time to word end (s), word duration (s), relative progress in [0, 1),
        speaking rate (syllables/s) of the word; zeros outside words.
    filler : ndarray [shape=(T,)], bool
        Frame lies in a filler word.
    """
    feats = np.zeros((n_frames, 5), np.float32)
    filler = np.zeros(n_frames, bool)
    if not words or n_frames == 0:
        return feats, filler
    times = np.arange(n_frames) / fps
    starts = np.array([w.start_s for w in words])
    ends = np.array([w.end_s for w in words])
    k = np.searchsorted(starts, times, side="right") - 1
    kk = np.maximum(k, 0)
    inside = (k >= 0) & (times < ends[kk])
    dur = ends - starts
    rate = np.array([w.syllables for w in words]) / dur
    since = times - starts[kk]
    cols = np.stack([since, ends[kk] - times, dur[kk], since / dur[kk], rate[kk]], axis=1)
    feats[inside] = cols[inside]
    filler[inside] = np.array([w.is_filler for w in words])[kk[inside]]
    return feats, filler


def span_mask(spans: Sequence[tuple[float, float]], n_frames: int, fps: float) -> np.ndarray:
    """Frames whose time ``t / fps`` lies in any ``[start, end)`` span; ndarray [shape=(T,)], bool."""
    mask = np.zeros(n_frames, bool)
    times = np.arange(n_frames) / fps
    for a, b in spans:
        mask |= (times >= a) & (times < b)
    return mask


def speech_features(
    acoustic: dict[str, np.ndarray],
    words: Sequence[Word],
    spans: Sequence[tuple[float, float]],
    n_frames: int,
    fps: float,
) -> SpeechFeatures:
    """The frame features of an utterance (batch or streamed) from its acoustic arrays, words and silent spans.

    Parameters
    ----------
    acoustic : dict of str to ndarray
        ``mel_db`` [shape=(T, n_mels)], ``mfcc`` [shape=(T, 37)], ``rms`` [shape=(T,)], ``pitch_hz`` [shape=(T,)].
    words : sequence of Word
    spans : sequence of (start_s, end_s), seconds
    n_frames : int
    fps : float, frames/s
    """
    wf, filler = word_features(words, n_frames, fps)
    return SpeechFeatures(
        fps=float(fps),
        mel_db=acoustic["mel_db"],
        mfcc=acoustic["mfcc"],
        rms=acoustic["rms"],
        pitch_hz=acoustic["pitch_hz"],
        word_features=wf,
        filler=filler,
        silence=span_mask(spans, n_frames, fps),
    )
