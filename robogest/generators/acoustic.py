"""Acoustic beats for the default generator: where a stroke may land.

A stroke belongs on a syllable that is being stressed, which in the signal is a sharp rise of loudness in
the voiced band (vowel onsets, Rhythmic Gesticulator §4.2.1 uses onsets too). This detector is our own and
deliberately not the evaluation's: it looks at the loudness of the 300-3000 Hz band (10 ms hop, 30 ms
window), smoothed, and takes local maxima of its rate of rise that lift the band by at least
``min_rise_db`` to a level well above the quiet frames, at least ``min_gap_s`` apart. It never inserts
pseudo-beats: a stretch without a rise gets no stroke (the generator holds instead). The quiet and loud levels
are those of the audio heard: a live stream's zero padding for speech still to come is left out of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from scipy.signal import butter, find_peaks, sosfiltfilt

HOP_S = 0.01
WINDOW_S = 0.03


@dataclass(frozen=True)
class AcousticBeats:
    """Beat times and how prominent each is.

    Attributes
    ----------
    t_s : ndarray [shape=(B,)], seconds
        Increasing beat times (the steepest point of each loudness rise).
    prominence : ndarray [shape=(B,)]
        In [0, 1]: size of the rise and loudness reached, relative to the utterance.
    """

    t_s: np.ndarray
    prominence: np.ndarray


def band_loudness_db(audio: np.ndarray, sr: int) -> np.ndarray:
    """Loudness of the 300-3000 Hz band, dB, one value every :data:`HOP_S` (frame ``i`` centred at ``i * HOP_S``).

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float in [-1, 1]
    sr : int
        Sample rate, Hz (at least 8 kHz).
    """
    a = np.asarray(audio, dtype=np.float64).ravel()
    hop, win = max(1, round(HOP_S * sr)), max(2, round(WINDOW_S * sr))
    if a.size < win:
        return np.zeros(0)
    a = sosfiltfilt(butter(2, [300.0, min(3000.0, 0.45 * sr)], btype="band", fs=sr, output="sos"), a)
    a = np.pad(a, (win // 2, win // 2))
    n = 1 + (a.size - win) // hop
    frames = np.lib.stride_tricks.sliding_window_view(a, win)[::hop][:n]  # (F, win)
    power: npt.NDArray[np.float64] = np.mean(frames**2, axis=1)  # (F,)
    return 20.0 * np.log10(np.sqrt(power) + 1e-6)


def acoustic_beats(
    audio: np.ndarray,
    sr: int,
    silent_spans: tuple[tuple[float, float], ...] = (),
    min_gap_s: float = 0.2,
    min_rise_db: float = 4.0,
    smooth_s: float = 0.015,
    loudness_db: np.ndarray | None = None,
    heard_s: float | None = None,
) -> AcousticBeats:
    """Stressable syllable onsets of an utterance (see the module docstring).

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float in [-1, 1]
    sr : int
    silent_spans : tuple of (start_s, end_s)
        No beat inside these (with 50 ms of margin).
    min_gap_s : float
        Beats closer than this keep only the steeper rise.
    min_rise_db : float
        A rise must lift the band loudness by this much over ±50 ms.
    smooth_s : float
        Gaussian smoothing of the loudness track, seconds.
    loudness_db : ndarray [shape=(F,)], dB, optional
        :func:`band_loudness_db` of ``audio`` when the caller already has it (it is most of the cost).
    heard_s : float, optional
        Only the first ``heard_s`` seconds were heard (a stream's partial utterance, padded with zeros): the
        levels a rise is judged against come from them. (Counted, 1.5 s of padding pulled the quiet level from
        about -50 to -120 dB, so a stream's plans took weak rises for beats that the whole utterance does not.)

    Returns
    -------
    AcousticBeats
        Empty for silence or audio shorter than one window. Works on a partial utterance too (beats in
        its last 50 ms are not final yet).
    """
    db = band_loudness_db(audio, sr) if loudness_db is None else loudness_db
    heard = np.arange(db.size) * HOP_S < (np.inf if heard_s is None else heard_s)
    if heard.sum() < 5:  # also too short audio
        return AcousticBeats(np.zeros(0), np.zeros(0))
    db = gaussian_filter1d(db, smooth_s / HOP_S)
    rate = np.gradient(db) / HOP_S  # dB/s
    quiet, loud = np.percentile(db[heard], 20), np.percentile(db[heard], 97)
    k = round(0.05 / HOP_S)
    idx, _ = find_peaks(rate, height=0.0, distance=max(1, round(min_gap_s / HOP_S)))
    after = db[np.minimum(idx + k, db.size - 1)]
    rise = after - db[np.maximum(idx - k, 0)]
    keep = (rise >= min_rise_db) & (after > quiet + 0.35 * (loud - quiet))
    idx, rise, after = idx[keep], rise[keep], after[keep]
    t = idx * HOP_S
    ok = np.ones(t.size, dtype=bool)
    for a, b in silent_spans:
        ok &= ~((t > a + 0.05) & (t < b - 0.05)) if b - a > 0.1 else ok
    t, rise, after = t[ok], rise[ok], after[ok]
    if t.size == 0:
        return AcousticBeats(np.zeros(0), np.zeros(0))
    r = np.clip((rise - min_rise_db) / 20.0, 0.0, 1.0)
    level = np.clip((after - quiet) / max(loud - quiet, 1e-6), 0.0, 1.0)
    return AcousticBeats(t, 0.5 * r + 0.5 * level)
