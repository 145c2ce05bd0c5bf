"""Volume track, environmental-noise level and silent periods.

The fine volume track (RMS every ``onset_hop_s`` = 10 ms over a 25 ms window) serves the noise
estimate, the beat rule and silence detection, so all three agree on what "loud" means.

Noise level Ĩ_a (Rhythmic Gesticulator §4.2.1 calls it the average volume of the environmental noise)
is estimated as a low percentile (``noise_percentile``, default 10) of that track, floored at
``noise_floor_db`` so digital silence still gives a positive level. A frame is *active* when its RMS
exceeds ``Ĩ_a * 10**(speech_margin_db / 20)`` (12 dB above the noise by default), capped at
``max_speech_threshold_db`` (-40 dBFS) so a file without any pause is not judged silent against itself.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from robogest.speech.config import SpeechConfig
from robogest.speech.types import Word

#: Window of the fine volume track, s.
FINE_WINDOW_S = 0.025


def frame_rms(audio: np.ndarray, sr: int, hop: int, win: int) -> np.ndarray:
    """Centred frame RMS, frame ``i`` at sample ``i * hop`` (zero padding at the edges).

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
    sr : int
        Sample rate, Hz (only for the caller's bookkeeping; frames are in samples).
    hop, win : int
        Hop and window, samples.

    Returns
    -------
    ndarray [shape=(1 + N // hop,)], linear amplitude
    """
    del sr
    n = audio.shape[0]
    n_frames = 1 + n // hop
    # Cumulative sum of squares in float64 makes any window length O(N).
    csum = np.concatenate(([0.0], np.cumsum(audio.astype(np.float64) ** 2)))
    centres = np.arange(n_frames) * hop
    lo = np.clip(centres - win // 2, 0, n)
    hi = np.clip(centres - win // 2 + win, 0, n)
    energy = np.maximum(csum[hi] - csum[lo], 0.0)
    rms: np.ndarray = np.sqrt(energy / win).astype(np.float32)
    return rms


def fine_volume(audio: np.ndarray, sr: int, config: SpeechConfig) -> tuple[np.ndarray, float]:
    """Fine volume track used for noise, beats and silence.

    Returns
    -------
    volume : ndarray [shape=(V,)], linear amplitude
        RMS every ``hop`` samples, frame ``i`` at ``i * hop / sr`` s.
    rate : float
        Frames per second of ``volume`` (``sr / hop``).
    """
    hop = max(1, round(config.onset_hop_s * sr))
    win = max(hop, round(FINE_WINDOW_S * sr))
    return frame_rms(audio, sr, hop, win), sr / hop


def estimate_noise_level(volume: np.ndarray, config: SpeechConfig) -> float:
    """Environmental-noise level Ĩ_a, linear amplitude (see module docstring); never below the floor."""
    if volume.size == 0:
        return config.noise_floor
    return float(max(np.percentile(volume, config.noise_percentile), config.noise_floor))


def activity_threshold(noise_level: float, config: SpeechConfig) -> float:
    """RMS above which a frame counts as speech rather than noise, linear amplitude."""
    margin = noise_level * 10.0 ** (config.speech_margin_db / 20.0)
    return float(min(margin, 10.0 ** (config.max_speech_threshold_db / 20.0)))


def find_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index runs ``[i0, i1)`` where ``mask`` is True."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


def silent_spans(
    volume: np.ndarray,
    rate: float,
    threshold: float,
    duration_s: float,
    min_silence_s: float,
    words: Sequence[Word] = (),
) -> tuple[tuple[float, float], ...]:
    """Spans with no speech: volume at or below ``threshold`` and no word overlapping, >= ``min_silence_s``.

    Parameters
    ----------
    volume : ndarray [shape=(V,)], linear amplitude
        Fine volume track, frame ``i`` at ``i / rate`` s.
    rate : float
        Frames per second of ``volume``.
    threshold : float
        Activity threshold, linear amplitude.
    duration_s : float
        Audio length; spans are clipped to ``[0, duration_s]`` and leading/trailing silence counts.
    min_silence_s : float
        Shortest reported span, s.
    words : sequence of Word
        Frames inside a word are speech whatever their volume.

    Returns
    -------
    tuple of (start_s, end_s)
        Increasing, non-overlapping spans. A quiet frame ``i`` stands for ``[(i - 0.5) / rate, (i + 0.5) / rate)``.
    """
    quiet = np.asarray(volume) <= threshold
    times = np.arange(quiet.shape[0]) / rate
    starts = np.array([w.start_s for w in words], dtype=np.float64)
    ends = np.array([w.end_s for w in words], dtype=np.float64)
    if len(words):  # frames overlapping a word, as index ranges: linear in words + frames (a mask per word was not)
        lo = np.searchsorted(times + 0.5 / rate, starts, side="right")  # first frame ending after the word's start
        hi = np.searchsorted(times - 0.5 / rate, ends, side="left")  # first frame starting at or after its end
        keep = lo < hi
        inside = np.zeros(quiet.shape[0] + 1, dtype=np.int64)
        np.add.at(inside, lo[keep], 1)
        np.add.at(inside, hi[keep], -1)
        quiet &= np.cumsum(inside[:-1]) == 0
    spans: list[tuple[float, float]] = []
    by_end, by_start = np.argsort(ends, kind="stable"), np.argsort(starts, kind="stable")
    for i0, i1 in find_runs(quiet):
        start = 0.0 if i0 == 0 else max(0.0, (i0 - 0.5) / rate)
        end = duration_s if i1 == quiet.shape[0] else min(duration_s, (i1 - 0.5) / rate)
        # snap to word edges within a frame (the mask above rounds to whole frames)
        start = _snap(start, ends, by_end, ends[by_end], lambda i, x: starts[i] < x, 1.0 / rate)
        end = _snap(end, starts, by_start, starts[by_start], lambda i, x: ends[i] > x, 1.0 / rate)
        if end - start >= min_silence_s - 1e-9:
            spans.append((float(start), float(end)))
    return tuple(spans)


def _snap(
    x: float,
    edges: np.ndarray,
    order: np.ndarray,
    sorted_edges: np.ndarray,
    ok: Callable[[int, float], bool],
    tol: float,
) -> float:
    """``x`` moved as a loop over the words in list order moves it: to ``edges[i]`` of each word ``i`` whose edge is
    within ``tol`` of the current ``x`` and ``ok(i, x)``; only the words near ``x`` are looked at (``order``
    sorts ``edges``; ``sorted_edges`` is ``edges[order]``), so a span costs no pass over all the words."""
    done = -1
    while True:
        a = np.searchsorted(sorted_edges, x - tol, side="left")
        b = np.searchsorted(sorted_edges, x + tol, side="right")
        near = np.sort(order[a:b])
        hit = next((int(i) for i in near[near > done] if ok(int(i), x)), None)
        if hit is None:
            return x
        x, done = float(edges[hit]), hit


def active_regions(
    volume: np.ndarray, rate: float, threshold: float, duration_s: float, min_gap_s: float
) -> tuple[tuple[float, float], ...]:
    """Voiced regions: the complement of :func:`silent_spans` (without words) inside ``[0, duration_s]``."""
    spans = silent_spans(volume, rate, threshold, duration_s, min_gap_s)
    regions: list[tuple[float, float]] = []
    t = 0.0
    for a, b in spans:
        if a > t:
            regions.append((t, a))
        t = b
    if duration_s > t:
        regions.append((t, duration_s))
    # A region must hold at least one active frame (guards against slivers between spans).
    times = np.arange(volume.shape[0]) / rate
    loud = volume > threshold
    return tuple((a, b) for a, b in regions if np.any(loud[(times >= a) & (times < b)]))
