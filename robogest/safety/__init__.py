"""Safety layer: between retargeting and any backend, every command respects the robot's limits.

:func:`apply_safety` runs, vectorised over the whole trajectory: position clamp (with margin) → Gaussian
smoothing → velocity clamp → silent-period rest targets → :func:`track`, a discrete-time tracking filter that
meets position, velocity and acceleration limits simultaneously. NaN/inf input is a :class:`SafetyError`,
never a command. :class:`SafetyStage` runs the same stages chunk by chunk (a stream) or whole (``apply_safety``).
"""

from robogest.safety.fit import fit_within_limits
from robogest.safety.limits import JointLimits, SafetyConfig, opencv_sigma
from robogest.safety.pipeline import SafetyResult, apply_safety
from robogest.safety.rest import long_silent_spans, rest_decisions, silent_rest_targets
from robogest.safety.stage import SafetyStage
from robogest.safety.stages import (
    check_limits,
    clamp_positions,
    clamp_velocity,
    gaussian_kernel,
    limit_acceleration,
    rest_reach_time_s,
    smooth,
    track,
)

__all__ = [
    "JointLimits",
    "SafetyConfig",
    "SafetyResult",
    "SafetyStage",
    "apply_safety",
    "check_limits",
    "clamp_positions",
    "clamp_velocity",
    "fit_within_limits",
    "gaussian_kernel",
    "limit_acceleration",
    "long_silent_spans",
    "opencv_sigma",
    "rest_decisions",
    "rest_reach_time_s",
    "silent_rest_targets",
    "smooth",
    "track",
]
