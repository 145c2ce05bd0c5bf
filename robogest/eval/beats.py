"""Speech-gesture beat synchrony: motion beats, PMB, BeatAlign, and their chance-corrected versions.

Why chance correction: speech has ~3 onsets/s, so with PMB's default δ = 0.2 s a motion beat placed at random
already lies within δ of some audio beat most of the time (the ±0.2 s windows around 3 beats/s cover most
of the timeline). A raw PMB of 80 % therefore says little. :func:`chance_corrected` compares the score of
the aligned motion with the same score after circularly shifting the motion beats in time by ≥ 2 s; the
shift keeps the motion's own rhythm and density but destroys its alignment to speech, so the z-score
measures synchrony beyond what beat density alone buys.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from robogest.errors import InputError

#: PMB threshold, seconds (Rhythmic Gesticulator §7.3.2 default).
PMB_DELTA_S = 0.2
#: BeatAlign Gaussian width, seconds; see :func:`beat_align`.
BEAT_ALIGN_SIGMA_S = 0.3
#: Stroke sync: a wrist-speed peak is a hit when an audio event lies this many seconds after it (from, to).
#: The gesture leads: a stroke ends at (does not follow) the prominent syllable (McNeill 1992's phonological
#: synchrony rule; Leonard & Cummins 2011 find the hand's apex at the stressed syllable), and its speed peak
#: lies about mid-stroke, so before the syllable by up to about half a stroke (~0.2 s). See :func:`stroke_sync`.
STROKE_SYNC_WINDOW_S = (0.0, 0.2)
#: Sample rate the stroke-sync onset detector runs at (its settings are librosa's defaults at this rate).
ONSET_SR = 22050
#: A wrist-speed peak must stand this far (m/s) above its surroundings to count as a stroke, not drift.
STROKE_MIN_PROMINENCE_M_S = 0.05


def _speed_curve(pos: np.ndarray, fps: float, joints: Sequence[int] | None, smooth_s: float) -> np.ndarray:
    pos = np.asarray(pos, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[0] < 3:
        raise InputError(f"motion beats need (T >= 3, J, D) positions, got shape {pos.shape}")
    if joints is not None:
        pos = pos[:, list(joints)]
    speed: np.ndarray = np.linalg.norm(np.gradient(pos, axis=0), axis=-1).mean(axis=1) * fps  # (T,), frame-aligned
    if smooth_s > 0:
        speed = gaussian_filter1d(speed, smooth_s * fps, mode="nearest")
    return speed


def _prominence(curve: np.ndarray, rel_prominence: float) -> float:
    return rel_prominence * float(np.ptp(curve)) if curve.size else 0.0


def motion_beats(
    pos: np.ndarray,
    fps: float,
    joints: Sequence[int] | None = None,
    smooth_s: float = 0.05,
    rel_prominence: float = 0.02,
) -> np.ndarray:
    """Kinematic motion beats: local minima of the smoothed mean joint speed.

    Ho et al. (2013) and Davis & Agrawala (2018), used by Rhythmic Gesticulator eq. 22 and AIST++/BEAT,
    put a motion beat where the motion stops decelerating, i.e. at a local minimum of kinematic velocity.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, D)]
        Joint positions (metres) or joint angles (``(T, J, 1)`` radians); only the shape of the speed
        curve matters.
    fps : float
    joints : sequence of int, optional
        Joints averaged (default all).
    smooth_s : float
        Gaussian smoothing sigma, seconds; removes mocap jitter that would create spurious minima.
    rel_prominence : float
        A minimum must be at least this fraction of the curve's range deep, so a still body gives no beats.

    Returns
    -------
    ndarray [shape=(N_m,)], seconds
        Increasing beat times.
    """
    v = _speed_curve(pos, fps, joints, smooth_s)
    idx, _ = find_peaks(-v, prominence=max(_prominence(v, rel_prominence), 1e-9))
    return np.asarray(idx, dtype=np.int64) / fps


def pmb(motion_beats_s: np.ndarray, audio_beats_s: np.ndarray, delta_s: float = PMB_DELTA_S) -> float:
    """Percentage of matched beats (Rhythmic Gesticulator eq. 22), in %.

    Motion beats are visited in time order; each is matched to the first audio beat after the previously
    matched one that lies within ``delta_s``. So each audio beat is used at most once and matches keep their
    order, which is what the index ``j ≥ j*_{i-1} + 1`` in eq. 22 expresses.

    Parameters
    ----------
    motion_beats_s : ndarray [shape=(N_m,)], seconds
    audio_beats_s : ndarray [shape=(N_a,)], seconds
    delta_s : float
        Match threshold, seconds.

    Returns
    -------
    float
        Matched motion beats / N_m × 100; NaN if there are no motion beats.
    """
    mb = np.sort(np.asarray(motion_beats_s, dtype=np.float64).ravel())
    ab = np.sort(np.asarray(audio_beats_s, dtype=np.float64).ravel())
    if mb.size == 0:
        return float("nan")
    matched, j0 = 0, 0
    for b in mb:
        j = int(np.searchsorted(ab, b - delta_s, side="right"))  # first audio beat with a > b - δ
        j = max(j, j0)
        if j < ab.size and abs(ab[j] - b) < delta_s:
            matched += 1
            j0 = j + 1
    return 100.0 * matched / mb.size


def pmb_curve(motion_beats_s: np.ndarray, audio_beats_s: np.ndarray, deltas_s: np.ndarray | None = None) -> dict:
    """PMB as a function of δ (Rhythmic Gesticulator Fig. 11); returns ``delta_s`` and ``pmb`` arrays."""
    deltas = np.linspace(0.02, 0.5, 25) if deltas_s is None else np.asarray(deltas_s, dtype=np.float64)
    return {"delta_s": deltas, "pmb": np.array([pmb(motion_beats_s, audio_beats_s, d) for d in deltas])}


def beat_align(motion_beats_s: np.ndarray, audio_beats_s: np.ndarray, sigma_s: float = BEAT_ALIGN_SIGMA_S) -> float:
    """Beat alignment score as used for the BEAT dataset (Liu et al. 2022, after AIST++).

    ``mean over audio beats a of exp(-min_m (a - m)² / (2 σ²))`` in [0, 1]. AIST++ wrote σ in frames (3 at
    60 fps); BEAT works in seconds and its released evaluation code uses σ = 0.3 s, which we keep so numbers
    are comparable with papers reporting BEAT's BeatAlign. Note that 0.3 s is wide against ~3 onsets/s, so
    read it together with its chance-corrected z-score.

    Returns
    -------
    float
        NaN if there are no audio beats, 0 if there are no motion beats.
    """
    mb = np.asarray(motion_beats_s, dtype=np.float64).ravel()
    ab = np.asarray(audio_beats_s, dtype=np.float64).ravel()
    if ab.size == 0:
        return float("nan")
    if mb.size == 0:
        return 0.0
    d2 = np.min((ab[:, None] - mb[None, :]) ** 2, axis=1)
    return float(np.mean(np.exp(-d2 / (2.0 * sigma_s**2))))


def circular_shifts(duration_s: float, n_shifts: int = 100, min_shift_s: float = 2.0) -> np.ndarray:
    """``n_shifts`` shifts evenly spread over ``[min_shift_s, duration_s - min_shift_s]`` (empty if too short)."""
    if duration_s - 2 * min_shift_s <= 0 or n_shifts < 1:
        return np.zeros(0)
    return np.linspace(min_shift_s, duration_s - min_shift_s, n_shifts)


def chance_corrected(
    score_fn: Callable[[np.ndarray, np.ndarray], float],
    motion_beats_s: np.ndarray,
    audio_beats_s: np.ndarray,
    duration_s: float,
    n_shifts: int = 100,
    min_shift_s: float = 2.0,
) -> dict:
    """A beat score beside its distribution under circular time shifts of the motion.

    Parameters
    ----------
    score_fn : callable ``(motion_beats_s, audio_beats_s) -> float``
        E.g. ``lambda m, a: pmb(m, a, 0.2)``.
    motion_beats_s, audio_beats_s : ndarray, seconds
    duration_s : float
        Length of the motion; beats wrap around modulo this.
    n_shifts : int
        Number of shifts, spread evenly over ``[min_shift_s, duration_s - min_shift_s]``.
    min_shift_s : float
        Smallest shift; ≥ 2 s keeps the shifted beats clear of the true alignment (gesture-speech lag is
        a few hundred ms).

    Returns
    -------
    dict
        ``score`` (aligned), ``null_mean``, ``null_std``, ``z`` = (score - null_mean) / null_std (NaN when
        the motion is shorter than 2 × ``min_shift_s`` or the null has no spread), ``n_shifts``.
    """
    mb = np.asarray(motion_beats_s, dtype=np.float64).ravel()
    ab = np.asarray(audio_beats_s, dtype=np.float64).ravel()
    score = float(score_fn(mb, ab))
    shifts = circular_shifts(duration_s, n_shifts, min_shift_s)
    null = np.array([score_fn(np.sort((mb + s) % duration_s), ab) for s in shifts])
    null = null[np.isfinite(null)]
    if null.size < 2:
        return {"score": score, "null_mean": float("nan"), "null_std": float("nan"), "z": float("nan"), "n_shifts": 0}
    mu, sd = float(null.mean()), float(null.std(ddof=1))
    z = (score - mu) / sd if sd > 0 and np.isfinite(score) else float("nan")
    return {"score": score, "null_mean": mu, "null_std": sd, "z": float(z), "n_shifts": int(null.size)}


def beat_sync_report(
    pos: np.ndarray,
    fps: float,
    audio_beats_s: np.ndarray,
    wrists: Sequence[int] | None = None,
    n_shifts: int = 100,
    min_shift_s: float = 2.0,
    delta_s: float = PMB_DELTA_S,
    sigma_s: float = BEAT_ALIGN_SIGMA_S,
    onsets_s: np.ndarray | None = None,
    silent_spans: Sequence[tuple[float, float]] = (),
) -> dict:
    """Every beat score of a motion against audio beats, each with its chance correction.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, D)]
        Joint positions, metres (or angles ``(T, J, 1)``, radians, for robot trajectories).
    fps : float
    audio_beats_s : ndarray [shape=(N_a,)], seconds
        Onset beats only: pseudo-beats (inserted into long gaps) are no audio events and must not be
        passed here.
    wrists : sequence of int, optional
        Wrist joints (positions in metres) for :func:`stroke_sync`; needs ``onsets_s`` too.
    onsets_s : ndarray [shape=(K,)], seconds, optional
        Events from :func:`stroke_sync_events` for the stroke sync.
    silent_spans : sequence of (start_s, end_s)
        Excluded from the stroke sync.

    Returns
    -------
    dict
        ``pmb`` (kinematic beats, δ = ``delta_s``), ``beat_align`` (kinematic beats, σ = ``sigma_s``), each a
        :func:`chance_corrected` dict; ``stroke_sync`` (with ``wrists`` and ``onsets_s``);
        ``n_motion_beats``, ``n_audio_beats``, ``motion_beats_s``, ``pmb_curve``.
    """
    duration = pos.shape[0] / fps
    ab = np.asarray(audio_beats_s, dtype=np.float64).ravel()
    mb = motion_beats(pos, fps)
    out = {
        "n_motion_beats": int(mb.size),
        "n_audio_beats": int(ab.size),
        "motion_beats_s": mb,
        "pmb_curve": pmb_curve(mb, ab),
        "pmb": {"delta_s": delta_s}
        | chance_corrected(lambda m, a: pmb(m, a, delta_s), mb, ab, duration, n_shifts, min_shift_s),
        "beat_align": {"sigma_s": sigma_s}
        | chance_corrected(lambda m, a: beat_align(m, a, sigma_s), mb, ab, duration, n_shifts, min_shift_s),
    }
    if wrists is not None and onsets_s is not None:
        out["stroke_sync"] = stroke_sync(pos[:, list(wrists)], fps, onsets_s, silent_spans, n_shifts, min_shift_s)
    return out


def audio_onsets(audio: np.ndarray, sr: int) -> np.ndarray:
    """Audio onsets, :func:`stroke_sync`'s fallback events, from a detector no generator uses to place strokes.

    ``librosa.onset.onset_detect`` with librosa's default settings on the audio resampled to
    :data:`ONSET_SR` (22 050 Hz): spectral flux of a 128-band mel spectrogram (n_fft 2048, hop 512 =
    23 ms, lag 1, no max filter) with librosa's default peak picking (pre/post max 30 ms, pre-avg 100 ms,
    post-avg 100 ms, delta 0.07, wait 30 ms). The speech front-end's beats (40 mel bands at the feature
    hop, gated by the activity threshold) and the default generator's acoustic beats (rises of the
    loudness envelope) are different detectors, so the metric does not score a generator against the
    very times it aimed at.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float in [-1, 1]
    sr : int
        Sample rate, Hz.

    Returns
    -------
    ndarray [shape=(K,)], seconds
    """
    import librosa

    y = np.asarray(audio, dtype=np.float32).ravel()
    if y.size == 0 or not np.any(y):
        return np.zeros(0)
    if sr != ONSET_SR:
        y = librosa.resample(y, orig_sr=sr, target_sr=ONSET_SR)
    return np.asarray(librosa.onset.onset_detect(y=y, sr=ONSET_SR, units="time"), dtype=np.float64)


def stroke_peaks(wrist_pos: np.ndarray, fps: float, smooth_s: float = 0.05) -> np.ndarray:
    """Speed peaks of each wrist (pooled, sorted), seconds ``(N,)``.

    Each wrist is taken on its own (one hand often beats while the other holds); a peak must be at
    least :data:`STROKE_MIN_PROMINENCE_M_S` prominent, so idle drift and mocap jitter are not strokes.

    Parameters
    ----------
    wrist_pos : ndarray [shape=(T, W, 3)], metres
    fps : float
    smooth_s : float
        Gaussian smoothing sigma of each speed curve, seconds.
    """
    pos = np.asarray(wrist_pos, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[0] < 3:
        raise InputError(f"stroke sync needs (T >= 3, W, 3) wrist positions, got shape {pos.shape}")
    speed = np.linalg.norm(np.gradient(pos, axis=0), axis=-1) * fps  # (T, W) m/s
    out: list[np.ndarray] = []
    for k in range(speed.shape[1]):
        v = gaussian_filter1d(speed[:, k], smooth_s * fps, mode="nearest") if smooth_s > 0 else speed[:, k]
        idx, _ = find_peaks(v, prominence=STROKE_MIN_PROMINENCE_M_S)
        out.append(idx / fps)
    return np.sort(np.concatenate(out)) if out else np.zeros(0)


def in_speech(t: np.ndarray, silent_spans: Sequence[tuple[float, float]]) -> np.ndarray:
    """``(N,)`` whether each time of ``t (N,)`` s lies outside the silent spans."""
    ok = np.ones(t.shape, dtype=bool)
    for a, b in silent_spans:
        ok &= ~((t >= a) & (t < b))
    return ok


def stroke_hit_rate(
    peaks_s: np.ndarray,
    events_s: np.ndarray,
    silent_spans: Sequence[tuple[float, float]] = (),
    window_s: tuple[float, float] = STROKE_SYNC_WINDOW_S,
) -> float:
    """Fraction of the peaks during speech followed by an audio event: ``lo <= event - peak <= hi``.

    Parameters
    ----------
    peaks_s : ndarray [shape=(N,)], seconds
    events_s : ndarray [shape=(K,)], seconds
    silent_spans : sequence of (start_s, end_s)
        Peaks in these spans are not counted.
    window_s : (float, float), seconds
        ``(lo, hi)``: how long after the peak (negative: before) an event still makes it a hit.

    Returns
    -------
    float
        NaN when no peak is in speech.
    """
    lo, hi = window_s
    if hi < lo:
        raise InputError(f"stroke sync window {window_s}: the end must not precede the start")
    p = np.asarray(peaks_s, dtype=np.float64)
    p = p[in_speech(p, silent_spans)]
    ev = np.sort(np.asarray(events_s, dtype=np.float64).ravel())
    if p.size == 0:
        return float("nan")
    if ev.size == 0:
        return 0.0
    j = np.searchsorted(ev, p + lo, side="left")  # first event at or after peak + lo
    return float(np.mean((j < ev.size) & (ev[np.minimum(j, ev.size - 1)] - p <= hi)))


def stroke_sync(
    wrist_pos: np.ndarray,
    fps: float,
    onsets_s: np.ndarray,
    silent_spans: Sequence[tuple[float, float]] = (),
    n_shifts: int = 100,
    min_shift_s: float = 2.0,
    window_s: tuple[float, float] = STROKE_SYNC_WINDOW_S,
) -> dict:
    """Stroke sync: do the wrists' speed peaks during speech lead prominent syllables more than chance?

    A speed peak is a hit when an audio event (best: a stressed-vowel onset, see :func:`stroke_sync_events`)
    follows it within ``window_s`` (default 0 to 0.2 s, :data:`STROKE_SYNC_WINDOW_S`). The hit rate is
    compared with the hit rates of the same peaks circularly shifted in time by ``min_shift_s`` to
    ``duration - min_shift_s`` (the shift keeps the motion's own rhythm and density and the speech mask
    stays put, so only alignment is lost). No generator places strokes on stressed-vowel onsets from a
    forced alignment, so this is not circular.

    Validation status (issue 13 §1, ``benchmarks/diag_stroke_sync.py`` prints all ~500 variants tried). On
    the shared 63.5 s BEAT2 take (speaker "scott", 185 wrist peaks in speech), with its TextGrid's
    stressed-vowel onsets: motion capture z = +3.5 (hit 0.70, chance 0.57); first half +2.0, second half
    +3.4; the same motion shifted by every whole second from 2 to 61 s: |z| median 0.63, 87 % below 1.5,
    max 2.3. Marginal: sensitive to the window's end (0 to 0.15 s: whole take +1.5), and not a clean
    held-out result (the variant was picked after the second half had been looked at; the calibration-half
    winners, sparse librosa onsets, fail there). Against librosa's default onsets (4.3/s, chance hit rate
    0.75 at ±0.1 s) the take scores at chance (z = -0.7), and no audio-only detector tried held up on the
    second half, so without stressed-vowel timings the measure is not validated. For synthesized speech the
    events are eSpeak NG's stressed syllables (:func:`robogest.speech.synthesize_with_stress`): the same kind of
    event from another source, checked only to sit on loud voiced stretches (``benchmarks/diag_tts_stress.py``),
    not validated against motion.

    Parameters
    ----------
    wrist_pos : ndarray [shape=(T, W, 3)], metres
        Wrist positions (human wrists or robot wrist sites).
    fps : float
    onsets_s : ndarray [shape=(K,)], seconds
        Audio events, from :func:`stroke_sync_events`.
    silent_spans : sequence of (start_s, end_s)
        Peaks in these spans are not counted.
    n_shifts, min_shift_s : int, float
        The null distribution's shifts.
    window_s : (float, float), seconds
        Hit window, event time minus peak time.

    Returns
    -------
    dict
        ``hit`` (fraction), ``chance`` (mean null hit rate), ``chance_std``, ``z`` = (hit - chance) /
        chance_std (NaN if undefined), ``n_peaks`` (in speech), ``n_onsets``, ``window_s``, ``n_shifts``.
    """
    peaks = stroke_peaks(wrist_pos, fps)
    duration = np.asarray(wrist_pos).shape[0] / fps
    spans = [(float(a), float(b)) for a, b in silent_spans]
    win = (float(window_s[0]), float(window_s[1]))
    res = chance_corrected(
        lambda m, a: stroke_hit_rate(m, a, spans, win), peaks, onsets_s, duration, n_shifts, min_shift_s
    )
    return {
        "hit": res["score"],
        "chance": res["null_mean"],
        "chance_std": res["null_std"],
        "z": res["z"],
        "n_peaks": int(in_speech(peaks, spans).sum()),
        "n_onsets": int(np.asarray(onsets_s).size),
        "window_s": list(win),
        "n_shifts": res["n_shifts"],
    }


def stroke_sync_events(
    audio: np.ndarray,
    sr: int,
    transcript: str | Path | None = None,
    stressed_vowels_s: np.ndarray | None = None,
) -> tuple[np.ndarray, str]:
    """Audio events for :func:`stroke_sync` and which kind they are.

    Stressed-vowel onsets (kind ``"stressed_vowels"``), the only events the measure is validated with:
    ``stressed_vowels_s`` when given (for synthesized speech, from
    :func:`robogest.speech.synthesize_with_stress`), else the transcript's ``phones`` tier
    (:func:`robogest.speech.transcript.read_stressed_vowels`) where it has one. Otherwise :func:`audio_onsets`
    (kind ``"librosa_onsets"``), reported but not validated (see :func:`stroke_sync`).

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float in [-1, 1]
    sr : int
        Sample rate, Hz.
    transcript : path, optional
        Transcript file (a forced-alignment TextGrid with a ``phones`` tier gives stressed vowels).
    stressed_vowels_s : ndarray [shape=(K,)], seconds, optional
        Stressed-vowel onsets known from elsewhere (eSpeak's phoneme events for TTS clips).

    Returns
    -------
    (ndarray [shape=(K,)], seconds, str)
    """
    if stressed_vowels_s is not None:
        return np.sort(np.asarray(stressed_vowels_s, dtype=np.float64).ravel()), "stressed_vowels"
    if transcript is not None:
        from robogest.speech.transcript import read_stressed_vowels

        ev = read_stressed_vowels(transcript)
        if ev is not None:
            return ev, "stressed_vowels"
    return audio_onsets(audio, sr), "librosa_onsets"
