"""Objective metrics of co-speech gestures and robot command trajectories.

Metric functions are pure and take plain arrays (joint positions ``(T, J, 3)`` in metres, joint angles
``(T, J)`` in radians, times in seconds); :mod:`robogest.eval.report` combines them per file.
"""

from robogest.eval.beats import (
    BEAT_ALIGN_SIGMA_S,
    PMB_DELTA_S,
    audio_onsets,
    beat_align,
    beat_sync_report,
    chance_corrected,
    motion_beats,
    pmb,
    pmb_curve,
    stroke_peaks,
    stroke_sync,
    stroke_sync_events,
)
from robogest.eval.features import (
    diversity,
    feature_distances,
    frechet_distance,
    geometric_features,
    kinetic_features,
    lexeme_entropy,
    window_features,
)
from robogest.eval.kinematics import (
    hellinger_distance,
    maje_mad,
    maje_mad_s2ag_protocol,
    motion_statistics,
    silence_behaviour,
    speed_histogram,
    statistics_ratio,
    wrist_speed_comparison,
)
from robogest.eval.report import evaluate_motion, evaluate_trajectory
from robogest.eval.robot import joint_jerk, limit_violations, time_to_rest, tracking_error

__all__ = [
    "BEAT_ALIGN_SIGMA_S",
    "PMB_DELTA_S",
    "audio_onsets",
    "beat_align",
    "beat_sync_report",
    "chance_corrected",
    "diversity",
    "evaluate_motion",
    "evaluate_trajectory",
    "feature_distances",
    "frechet_distance",
    "geometric_features",
    "hellinger_distance",
    "joint_jerk",
    "kinetic_features",
    "lexeme_entropy",
    "limit_violations",
    "maje_mad",
    "maje_mad_s2ag_protocol",
    "motion_beats",
    "motion_statistics",
    "pmb",
    "pmb_curve",
    "silence_behaviour",
    "speed_histogram",
    "statistics_ratio",
    "stroke_peaks",
    "stroke_sync",
    "stroke_sync_events",
    "time_to_rest",
    "tracking_error",
    "window_features",
    "wrist_speed_comparison",
]
