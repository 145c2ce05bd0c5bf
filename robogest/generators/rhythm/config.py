"""Timing and style of the default generator, and the checks on them.

How each default was calibrated (benchmark, seeds, the values tried and what they gave) is in
``docs/rhythm-calibration.md``; here each field says what it does and why.
"""

from __future__ import annotations

from dataclasses import dataclass

from robogest.errors import InputError


@dataclass(frozen=True)
class RhythmConfig:
    """Timing and style of the default generator (seconds, radians).

    Calibrated on the first half (0-32 s) of the BEAT2 sample (speaker "scott") only; the measurements behind
    every default are in ``docs/rhythm-calibration.md``.
    """

    #: Output frame rate; None uses the speech's feature rate.
    fps: float | None = None
    #: A preparation peaks on an acoustic beat at most this long before its stroke starts; gaps longer than
    #: ``ready_after_s + 2 prep_s`` relax to READY on a free beat.
    prep_s: float = 1.2
    #: Shortest preparation.
    min_prep_s: float = 0.2
    #: Probability scale of gesturing on an ordinary beat: ``min(1, gesture_rate * (0.35 + 0.65 * prominence))``.
    gesture_rate: float = 2.5
    #: Global scale of every gesture offset.
    amplitude: float = 2.0
    #: Time allowed to reach rest after a silent period starts.
    retract_s: float = 0.5
    #: Rest is left this long before speech resumes.
    rest_lead_s: float = 0.35
    #: Silent periods at least this long are spent at rest; shorter pauses hold the ready pose.
    min_rest_span_s: float = 0.95
    #: After a hold, return to the ready pose if no preparation starts within this time.
    ready_after_s: float = 0.8
    #: Amplitude of idle breathing/sway while speaking.
    sway_rad: float = 0.05
    #: Probability of a small head beat on a prominent beat.
    head_beat_prob: float = 0.35
    #: Cap on the wrist speed peak of any move (the speaker's 99th percentile is ~2.1 m/s): moves are lengthened,
    #: or a gesture skipped, to stay under it.
    max_wrist_speed_m_s: float = 2.4
    #: Cap on the wrist acceleration peak of any move (the speaker's 99th percentile during speech); None: no cap.
    max_wrist_accel_m_s2: float | None = 15.0
    #: Multiplies every unit's stroke duration (longer strokes: lower acceleration, same beat timing).
    stroke_scale: float = 1.0
    #: Preparations peak at most at this fraction of ``max_wrist_speed_m_s``: the stroke stays the fastest phase.
    prep_speed_ratio: float = 0.7
    #: Multiplies every unit's post-stroke hold.
    hold_scale: float = 0.0
    #: Designer control in [0, 2]: beats get a gesture x amount as often, gestures are x (0.5 + 0.5 amount) as
    #: large; ``--style calm|neutral|lively`` = 0.5 / 1 / 1.5.
    amount: float = 1.0
    #: ``"auto"``, or ``"none"`` for idle breathing and the rest behaviour only.
    gestures: str = "auto"
    #: Speed limit of the body that will play the motion (e.g. a robot's slowest arm joint), on every move's
    #: largest angle change, so strokes are timed for it instead of smeared by its safety layer; None: no limit.
    max_joint_speed_rad_s: float | None = None
    #: Acceleration limit of that body, applied the same way; None: no limit.
    max_joint_accel_rad_s2: float | None = None
    #: ``"keywords"`` (trigger words only) or ``"embedding"``: a sentence with no trigger word gets the unit whose
    #: ``meaning`` is closest in MiniLM sentence embedding (needs the learn extra).
    semantic: str = "keywords"
    #: An arm stroke's wrist-speed peak comes this long before its acoustic beat (strokes end at the stressed
    #: syllable, McNeill 1992); tagged gestures and head moves stay on their beat.
    stroke_lead_s: float = 0.05
    #: Speed of each wrist's slow drift circle while speaking (m/s, times ``amount``): the hands are never still.
    drift_m_s: float = 0.45
    #: Frequency of the drift circle (radius about 10 cm at 0.3 m/s).
    drift_hz: float = 0.5
    #: In [0, 1]: the drift circle's radius is ``(1 - k + 2 k loud(t))`` times its own, so it follows the voice.
    drift_loudness: float = 0.6
    #: The drift circle turns this much further on each beat (and gives it back after), as a speaker's hands speed
    #: up on beats without a stroke; 0 turns it off.
    drift_beat_rad: float = 0.5
    #: Standard deviation of the Gaussian over which the drift's beat turn rises, seconds.
    drift_beat_s: float = 0.05
    #: ``drift_m_s`` for a live stream's plans, whose drift keeps the radius of mid loudness and speeds up on fewer
    #: beats (those heard or expected in time).
    live_drift_m_s: float = 0.3


def check_config(c: RhythmConfig) -> None:
    """Raise :class:`InputError` naming the first field of ``c`` out of its range (and the range)."""
    if not 0.0 <= c.amount <= 2.0:
        raise InputError(f"gesture amount must be within [0, 2], got {c.amount}")
    if c.gestures not in ("auto", "none"):
        raise InputError(f"gestures must be 'auto' or 'none', got {c.gestures!r}")
    if c.semantic not in ("keywords", "embedding"):
        raise InputError(f"semantic must be 'keywords' or 'embedding', got {c.semantic!r}")
    if not 0.0 <= c.drift_loudness <= 1.0:
        raise InputError(f"drift_loudness must be within [0, 1], got {c.drift_loudness}")
    if not (0.0 <= c.drift_beat_rad <= 1.0 and 0.01 <= c.drift_beat_s <= 0.2):
        raise InputError(
            f"drift_beat_rad must be within [0, 1] rad and drift_beat_s within [0.01, 0.2] s, got "
            f"{c.drift_beat_rad} and {c.drift_beat_s}"
        )
    if c.max_wrist_accel_m_s2 is not None and not c.max_wrist_accel_m_s2 > 0:
        raise InputError(f"max_wrist_accel_m_s2 must be above 0 m/s² (None: no cap), got {c.max_wrist_accel_m_s2}")
    if not 0.0 <= c.stroke_lead_s <= 0.5:
        raise InputError(f"stroke_lead_s must be within [0, 0.5] s, got {c.stroke_lead_s}")
    for key in ("drift_m_s", "live_drift_m_s"):  # a wrist speed: beyond 1 m/s the drift would be a gesture
        if not 0.0 <= getattr(c, key) <= 1.0:
            raise InputError(f"{key} must be within [0, 1] m/s, got {getattr(c, key)}")
