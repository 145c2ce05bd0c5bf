"""Idle motion while speaking: breathing/sway, and each wrist's slow drift circle, which follows the voice's
loudness and speeds up on the beats."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtr

from robogest.generators.acoustic import HOP_S
from robogest.generators.poses import DOF, N_DOF
from robogest.generators.rhythm.config import RhythmConfig

#: The drift gives back each beat's extra turn (``drift_beat_rad``) this long after the beat, seconds, over a
#: Gaussian of :data:`DRIFT_RETURN_WIDTH_S`; slow enough that the circle never turns backwards (0.5 rad over
#: 0.2 s is at most 1.0 rad/s against 3.1 rad/s at 0.5 Hz). Picked with the other drift values on the calibration
#: half: returning after 0.3 or 0.5 s, over 0.1 or 0.2 s, gave z 6.35-6.59 at 0.3 m/s.
DRIFT_RETURN_S = 0.3
DRIFT_RETURN_WIDTH_S = 0.2
#: Gaussian smoothing (s) of the loudness the drift's speed follows: phrase-level rises, not each syllable.
LOUDNESS_SMOOTH_S = 0.3
#: Band loudness (dB) below this is digital silence (a stream's zero padding), not part of the voice's range.
DIGITAL_SILENCE_DB = -100.0


def loudness(db: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The voice's loudness at ``t (T,)`` s, ``(T,)`` in [0, 1], from its band loudness ``db (F,)``
    (:func:`acoustic.band_loudness_db`): smoothed over :data:`LOUDNESS_SMOOTH_S`, 0 at its 20th and 1 at its
    95th percentile over the frames that are not digital silence (those count as quiet; zeros for too short
    audio)."""
    heard = db > DIGITAL_SILENCE_DB  # not digital silence (e.g. the zeros a stream pads unheard speech with)
    if heard.sum() < 5:
        return np.zeros(len(t))
    db = gaussian_filter1d(np.where(heard, db, np.percentile(db[heard], 20)), LOUDNESS_SMOOTH_S / HOP_S)
    lo, hi = np.percentile(db[heard], 20), np.percentile(db[heard], 95)
    loud = np.clip((db - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
    return np.asarray(np.interp(t, np.arange(db.size) * HOP_S, loud), dtype=float)


def sway(
    c: RhythmConfig,
    t: np.ndarray,
    rests: list[tuple[float, float]],
    rng: np.random.Generator,
    loud: np.ndarray,
    t0_s: float,
    beats_s: np.ndarray,
    drift_m_s: float,
) -> np.ndarray:
    """Idle breathing/sway ``(T, D)`` while speaking: fades in over 0.4 s away from rest, and is
    exactly zero inside rest windows and at both ends (the motion starts and ends at rest). ``loud (T,)``
    in [0, 1] is the voice's loudness, which the wrist drift's speed follows (``drift_loudness``); the drift
    also speeds up on each of ``beats_s (B,)``, seconds on ``t``'s clock (``drift_beat_rad``), and runs at
    ``drift_m_s`` (the config's, or ``live_drift_m_s`` for a live plan). Phases run
    on the utterance's clock (``t + t0_s``, ``t0_s`` = :attr:`Speech.offset_s`), so a streaming planner that
    generates from a later start gets the same sway where the two overlap."""
    end = t[-1] if len(t) else 0.0
    d = np.minimum(t, end - t)  # (T,) distance to the ends, s
    for r0, r1 in rests:
        d = np.minimum(d, np.clip(np.maximum(r0 - t, t - r1), 0, None))
    s = np.clip(d / 0.4, 0, 1)
    env = s**3 * (10 - 15 * s + 6 * s**2)  # (T,) minimum-jerk fade
    ph = rng.uniform(0, 2 * np.pi, 8)
    a = c.sway_rad
    out = np.zeros((len(t), N_DOF))
    ta = t + t0_s  # (T,) s on the utterance's clock
    out[:, DOF["spine_pitch"]] = 0.6 * a * np.sin(2 * np.pi * 0.23 * ta + ph[0])
    out[:, DOF["spine_yaw"]] = a * np.sin(2 * np.pi * 0.17 * ta + ph[1])
    out[:, DOF["head_pitch"]] = 0.5 * a * np.sin(2 * np.pi * 0.31 * ta + ph[2])
    out[:, DOF["head_yaw"]] = 0.8 * a * np.sin(2 * np.pi * 0.13 * ta + ph[3])
    _drift(c, out, t, ta, ph, loud, beats_s, drift_m_s)
    return np.asarray(out * env[:, None])


def _drift(
    c: RhythmConfig,
    out: np.ndarray,
    t: np.ndarray,
    ta: np.ndarray,
    ph: np.ndarray,
    loud: np.ndarray,
    beats_s: np.ndarray,
    drift_m_s: float,
) -> None:
    """Write each wrist's drift into ``out (T, D)`` (``ta (T,)``: ``t`` on the utterance's clock, ``ph (8,)`` the
    sway's phases).

    The hands never freeze while speaking. Each wrist circles slowly (elbow up/down and arm out/in in
    quadrature, levers ~0.27 m and ~0.4 m). At a steady angular rate a circle has a steady speed and no
    speed peaks of its own that could land off the beats; with drift_loudness its radius (so its speed)
    rises and falls with the voice's smoothed loudness, so what peaks it has lie in loud stretches. The
    radius, not the angular rate, follows the voice: a rate would have to be integrated from the start,
    so every replan of a stream that heard more would shift the circle's phase under the frames playing."""
    w = 2 * np.pi * c.drift_hz
    r = 0.0 if c.gestures == "none" else drift_m_s * c.amount / w  # circle radius, m (scales with amount)
    size = 1.0 - c.drift_loudness + 2.0 * c.drift_loudness * loud  # (T,) radius scale
    theta = w * ta
    if c.drift_beat_rad > 0:
        theta = theta + c.drift_beat_rad * beat_turns(t, np.asarray(beats_s) - c.stroke_lead_s, c.drift_beat_s)
    for k, side in enumerate("lr"):
        out[:, DOF[f"{side}_elbow"]] = r / 0.27 * size * np.sin(theta + ph[4 + 2 * k])
        out[:, DOF[f"{side}_abd"]] = r / 0.40 * size * np.cos(theta + ph[4 + 2 * k])


def beat_turns(t: np.ndarray, peaks_s: np.ndarray, sd: float) -> np.ndarray:
    """``(T,)``: how many beat turns the drift is ahead at ``t (T,)`` s: each peak in ``peaks_s (B,)`` adds one,
    rising over a Gaussian of ``sd`` (``drift_beat_s``) centred on it, and takes it back :data:`DRIFT_RETURN_S`
    later (see ``drift_beat_rad``); zero more than six widths from every beat."""
    out = np.zeros(len(t))
    lo = np.searchsorted(t, peaks_s - 6 * sd)
    hi = np.searchsorted(t, peaks_s + DRIFT_RETURN_S + 6 * DRIFT_RETURN_WIDTH_S)
    for p, i, j in zip(peaks_s, lo, hi, strict=True):
        u = t[i:j] - p
        out[i:j] += ndtr(u / sd) - ndtr((u - DRIFT_RETURN_S) / DRIFT_RETURN_WIDTH_S)
    return out
