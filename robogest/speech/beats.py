"""Speech beats after Rhythmic Gesticulator §4.2.1.

Rule (:func:`identify_beats`, a pure function):

1. An audio onset is a beat unless it is closer than D_m to the previous beat.
2. Every gap longer than D_M gets pseudo-beats: the next one goes at the first frame at least D_m after
   the previous beat (and at least D_m before the next beat) whose volume exceeds the noise level; this
   repeats until the remaining gap is at most D_M.
3. A stretch that is quiet throughout gets the minimal number of evenly spaced pseudo-beats,
   ``ceil(gap / D_M) - 1``, so no interval exceeds D_M.

Choices beyond the paper, all deliberate:

* The start and the end of the audio act as anchors (not beats), so the leading and trailing stretches
  are covered too and every interval on the whole timeline is at most D_M.
* Gaps inside silent periods get pseudo-beats like any other gap (the paper segments the whole
  recording into blocks at beats); :attr:`Speech.beat_is_pseudo` marks them so a generator can rest.
* The core passes the *activity* threshold (noise level plus a margin, see
  :mod:`robogest.speech.silence`) as the level, so background noise in a pause does not count as loud.
* A quiet stretch that ends in a loud frame more than D_M away gets the even pseudo-beats up to that
  frame, then a pseudo-beat on it.
"""

from __future__ import annotations

import math

import numpy as np

_EPS = 1e-9


def identify_beats(
    onset_times: np.ndarray,
    volume: np.ndarray,
    noise_level: float,
    fps: float,
    min_gap_s: float = 0.2,
    max_gap_s: float = 0.5,
    duration_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Beats and pseudo-beats from onsets (see module docstring for the rule).

    Parameters
    ----------
    onset_times : ndarray [shape=(K,)], seconds
        Audio onsets, any order; those outside ``[0, duration_s)`` are ignored.
    volume : ndarray [shape=(V,)], linear amplitude
        Volume of frame ``i``, at ``i / fps`` seconds.
    noise_level : float
        A frame is loud when ``volume > noise_level``.
    fps : float
        Frame rate of ``volume``, frames/s.
    min_gap_s, max_gap_s : float
        D_m and D_M, seconds.
    duration_s : float, optional
        Length of the timeline, seconds; ``V / fps`` when omitted.

    Returns
    -------
    beats_s : ndarray [shape=(B,)], seconds, float64
        Increasing beat times.
    is_pseudo : ndarray [shape=(B,)], bool
        True for inserted pseudo-beats.
    """
    if not 0.0 < min_gap_s < max_gap_s:
        raise ValueError("need 0 < min_gap_s < max_gap_s")
    volume = np.asarray(volume, dtype=np.float64)
    duration = float(volume.shape[0] / fps if duration_s is None else duration_s)
    loud_idx = np.flatnonzero(volume > noise_level)

    real = _spaced_onsets(onset_times, duration, min_gap_s)
    beats: list[float] = []
    pseudo: list[bool] = []
    anchors = [0.0, *real, duration]
    for j in range(len(anchors) - 1):
        a, b = anchors[j], anchors[j + 1]
        if j > 0:
            beats.append(a)
            pseudo.append(False)
        inserted = _pseudo_beats(a, b, loud_idx, fps, min_gap_s, max_gap_s)
        beats.extend(inserted)
        pseudo.extend([True] * len(inserted))
    return np.asarray(beats, dtype=np.float64), np.asarray(pseudo, dtype=bool)


def _spaced_onsets(onset_times: np.ndarray, duration: float, min_gap_s: float) -> list[float]:
    """The real beats: onsets within ``[0, duration)`` in time order, each at least D_m after the previous kept
    one (an onset closer than that belongs to the same beat)."""
    real: list[float] = []
    for t in np.sort(np.asarray(onset_times, dtype=np.float64)):
        if 0.0 <= t < duration and (not real or t - real[-1] >= min_gap_s - _EPS):
            real.append(float(t))
    return real


def _first_loud(loud_idx: np.ndarray, fps: float, t_from: float, t_to: float) -> float | None:
    """Time of the first loud frame (``loud_idx``: increasing indices) in ``[t_from, t_to]``, or None."""
    i0 = math.ceil(t_from * fps - _EPS)
    k = int(np.searchsorted(loud_idx, i0))
    if k < loud_idx.shape[0] and loud_idx[k] / fps <= t_to + _EPS:
        return float(loud_idx[k] / fps)
    return None


def _evenly(a: float, b: float, max_gap_s: float) -> list[float]:
    """The fewest evenly spaced times strictly between ``a`` and ``b`` that leave no gap over D_M."""
    n = max(0, math.ceil((b - a) / max_gap_s - _EPS) - 1)
    return [a + (b - a) * (j + 1) / (n + 1) for j in range(n)]


def _pseudo_beats(
    a: float, b: float, loud_idx: np.ndarray, fps: float, min_gap_s: float, max_gap_s: float
) -> list[float]:
    """Pseudo-beats between consecutive beats ``a`` and ``b`` so that no gap exceeds D_M: each at the first loud
    frame D_m..D_M after the previous one, else evenly spaced up to the next loud frame (or to ``b`` when quiet
    until then)."""
    out: list[float] = []
    cur = a
    while b - cur > max_gap_s + _EPS:
        lo, hi = cur + min_gap_s, b - min_gap_s
        if hi < lo:  # only when D_M < 2 D_m: one beat in the middle is the best possible
            out.append(0.5 * (cur + b))
            break
        t = _first_loud(loud_idx, fps, lo, min(cur + max_gap_s, hi))
        if t is not None:
            out.append(t)
            cur = t
            continue
        q = _first_loud(loud_idx, fps, cur + max_gap_s, hi)
        if q is None:  # quiet until the next beat
            out.extend(_evenly(cur, b, max_gap_s))
            break
        out.extend(_evenly(cur, q, max_gap_s))
        out.append(q)
        cur = q
    return out


def detect_onsets(audio: np.ndarray, sr: int, hop: int, envelope_max: float | None = None) -> np.ndarray:
    """Audio onsets: spectral flux on a mel spectrogram, peak picking (librosa's method, see :mod:`.dsp`).

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
    sr : int
        Sample rate, Hz.
    hop : int
        Onset envelope hop, samples.
    envelope_max : float, optional
        Scale of the onset envelope for peak picking. By default the envelope of ``audio`` is scaled to
        [0, 1] (the whole utterance offline); the streaming front-end passes the running maximum so that
        a short window is judged on the same scale.

    Returns
    -------
    ndarray [shape=(K,)], seconds
    """
    return onset_envelope_peaks(audio, sr, hop, envelope_max)[0]


def onset_envelope_peaks(
    audio: np.ndarray, sr: int, hop: int, envelope_max: float | None = None
) -> tuple[np.ndarray, float]:
    """:func:`detect_onsets` plus the largest envelope value of ``audio`` (0 when too short or silent)."""
    from robogest.speech import dsp

    if audio.shape[0] < 2 * hop or not np.any(audio):
        return np.zeros(0), 0.0
    n_fft = 1 << max(8, math.ceil(math.log2(4 * hop)))
    env = dsp.onset_strength(audio, sr, hop, n_fft, n_mels=40)
    peak = float(env.max() - env.min())
    if envelope_max is not None:
        env = (env - env.min()) / max(envelope_max, peak, 1e-12)
    frames = dsp.onset_detect(env, sr, hop, normalize=envelope_max is None)
    return np.asarray(frames, dtype=np.float64) * hop / sr, peak


def gate_onsets(
    onsets: np.ndarray, volume: np.ndarray, rate: float, threshold: float, look_ahead_s: float = 0.05
) -> np.ndarray:
    """Keep onsets followed within ``look_ahead_s`` by a frame louder than ``threshold``.

    Drops onsets that the detector finds in background noise during pauses.

    Parameters
    ----------
    onsets : ndarray [shape=(K,)], seconds
    volume : ndarray [shape=(V,)], linear amplitude, frame ``i`` at ``i / rate`` s
    """
    if onsets.size == 0 or volume.size == 0:
        return onsets[:0]
    i0 = np.clip(np.floor(onsets * rate).astype(int), 0, volume.shape[0] - 1)
    n = max(1, round(look_ahead_s * rate) + 1)
    idx = np.clip(i0[:, None] + np.arange(n)[None, :], 0, volume.shape[0] - 1)
    kept: np.ndarray = onsets[np.max(volume[idx], axis=1) > threshold]
    return kept
