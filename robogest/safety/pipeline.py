"""``apply_safety``: the one call between retargeting and any backend."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from robogest.errors import InputError, SafetyError
from robogest.safety.limits import JointLimits, SafetyConfig
from robogest.safety.rest import long_silent_spans
from robogest.safety.stage import SafetyStage, check_finite
from robogest.safety.stages import TOL


@dataclass(eq=False)
class SafetyResult:
    """What :func:`apply_safety` produced.

    Attributes
    ----------
    q_rad : ndarray [shape=(T', J)], radians
        Safe commands, ``T' ≥ T``: frames after the input's are the way back to rest (see ``n_extra_frames``).
    hold_rest : ndarray [shape=(T',)], bool
        Frames where the robot holds rest: inside a long silent period (or the final extension), exactly at
        ``rest_q_rad`` and unchanged since the previous frame.
    rest_target : ndarray [shape=(T',)], bool
        Frames whose target was rest (long silent periods up to the leave time, and the extension).
    long_silent : ndarray [shape=(T',)], bool
        Frames inside a silent run of at least ``rest_after_s`` (input frames only).
    fps : float, frames/s
    n_input_frames : int
    n_extra_frames : int
        Frames appended to bring the robot to rest and stop.
    clipped_fraction : float
        Fraction of input samples ``(frame, joint)`` that a limiting stage (position clamp, velocity clamp,
        preview fit and tracking outside rest targets) moved by more than 1e-6 rad.
    stage_changed_fraction : dict of str to float
        The same per stage: ``"clamp"``, ``"smooth"``, ``"velocity"`` (the rate limiter's change, reported even
        when ``preview`` bypasses it), ``"track"`` (fit and tracking together).
    """

    q_rad: np.ndarray
    hold_rest: np.ndarray
    rest_target: np.ndarray
    long_silent: np.ndarray
    fps: float
    n_input_frames: int
    n_extra_frames: int
    clipped_fraction: float
    stage_changed_fraction: dict[str, float] = field(default_factory=dict)

    @property
    def t_s(self) -> np.ndarray:
        """``(T',)`` sample times, seconds."""
        return np.arange(self.q_rad.shape[0]) / self.fps


def apply_safety(
    q: np.ndarray,
    limits: JointLimits,
    fps: float,
    silent: np.ndarray | None = None,
    q0: np.ndarray | None = None,
    config: SafetyConfig | None = None,
) -> SafetyResult:
    """Turn a retargeted motion into commands that respect every joint limit and rest in long silences.

    The whole motion goes through :class:`~robogest.safety.stage.SafetyStage` in one chunk (the stage the
    streaming planner runs per plan). Stages, in order: position clamp with margin → Gaussian smoothing → velocity
    clamp (without ``preview``) → silent-rest targets → with ``config.preview``,
    :func:`~robogest.safety.fit.fit_within_limits` (zero-lag fit within the limits) →
    :func:`~robogest.safety.stages.track` (velocity, acceleration and position limits at once, starting from ``q0``
    at standstill). Guarantees on ``q_rad`` (to 1e-9, rounding):

    * ``q_rad[0] == q0`` exactly; every sample within ``[q_min, q_max]`` and within the margin band widened to
      include rest (and ``q0``, which is only ever left inwards);
    * ``|Δq| ≤ v_max/fps`` and ``|Δ²q| ≤ a_max/fps²`` (the robot is taken as still before frame 0);
    * the last sample equals rest and equals the one before (zero velocity): if the input ends away from
      rest, **the output is longer than the input** by the frames needed to get there (``n_extra_frames``);
    * in every silent run ``[a, b)`` of at least ``rest_after_s``, every frame ``k`` with
      ``a + rest_reach_time_s(q_rad[a], limits, fps)·fps ≤ k`` and ``k/fps < b/fps − rest_leave_s`` is exactly at
      rest with zero velocity (runs reaching the end of the input hold to the end); shorter runs are
      not marked as holding unless rest is actually reached.

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
        Retargeted joint motion at ``fps``.
    limits : JointLimits
    fps : float, frames/s
    silent : ndarray [shape=(T,)], bool, optional
        Frames inside silent periods of any length; this function picks the long ones.
    q0 : ndarray [shape=(J,)], radians, optional
        The robot's current pose, within its limits; default rest (or the clamped first frame if
        ``config.start_from_rest`` is False).
    config : SafetyConfig, optional

    Returns
    -------
    SafetyResult

    Raises
    ------
    SafetyError
        NaN/inf in ``q`` or ``q0`` (the message names frames and joints), or ``q0`` outside the limits.
    InputError
        Shapes that do not match, or a bad ``fps``.
    """
    config = SafetyConfig() if config is None else config
    q, fps, silent = _checked_input(q, limits, fps, silent)
    stage = SafetyStage(limits, fps, config, q0)  # the one stage the stream uses too, here in one chunk
    out = np.vstack([stage.extend(q, silent, last=True), stage.finish()])
    if not (np.all(np.abs(out[-1] - limits.rest_q_rad) <= TOL)):  # guard: the tracker guarantees this
        raise SafetyError("safety: command trajectory does not end at rest (internal check)")
    return _result(stage, out, silent, q.shape[0])


def _checked_input(
    q: np.ndarray, limits: JointLimits, fps: float, silent: np.ndarray | None
) -> tuple[np.ndarray, float, np.ndarray]:
    """``(q (T, J), fps, silent (T,) bool)`` checked, or :class:`InputError`/:class:`SafetyError` naming the input."""
    q = np.asarray(q, dtype=float)
    n_j = limits.n_joints
    if q.ndim != 2 or q.shape[1] != n_j:
        raise InputError(f"safety: motion has shape {q.shape}, expected (T, {n_j}) for this robot's joints")
    if isinstance(fps, bool) or not (isinstance(fps, numbers.Real) and np.isfinite(fps) and fps > 0):
        raise InputError(f"safety: fps must be a finite number > 0, got {fps!r}")
    fps = float(fps)
    check_finite(q, limits, fps)
    n_t = q.shape[0]
    mask = np.zeros(n_t, dtype=bool) if silent is None else np.asarray(silent)
    if mask.shape != (n_t,):
        raise InputError(f"safety: silent mask has shape {mask.shape}, expected ({n_t},) to match the motion")
    return q, fps, mask.astype(bool)


def _result(stage: SafetyStage, out: np.ndarray, silent: np.ndarray, n_t: int) -> SafetyResult:
    """The :class:`SafetyResult` of a whole motion of ``n_t`` frames made safe by ``stage`` as ``out (T', J)``."""
    limits, fps = stage.limits, stage.fps
    n_out = out.shape[0]
    n_in_out = min(n_t, n_out)  # T == 0 still gives one frame (q0)
    rest_target_out = np.ones(n_out, dtype=bool)
    if n_t:
        rest_target_out[:n_t] = stage.rest_target
    long_silent = np.zeros(n_out, dtype=bool)
    for a, b in long_silent_spans(silent, fps, stage.config.rest_after_s):
        long_silent[a:b] = True
    at_rest = np.all(out == limits.rest_q_rad, axis=1)
    still = np.ones(n_out, dtype=bool)
    still[1:] = np.all(out[1:] == out[:-1], axis=1)
    c = stage.counts
    n_samples = max(c.samples, 1)
    stats = {"clamp": c.clamp, "smooth": c.smooth, "velocity": c.velocity, "track": c.track}
    return SafetyResult(
        q_rad=out,
        hold_rest=rest_target_out & at_rest & still,
        rest_target=rest_target_out,
        long_silent=long_silent,
        fps=fps,
        n_input_frames=n_t,
        n_extra_frames=n_out - n_in_out,
        clipped_fraction=c.any_limit / n_samples,
        stage_changed_fraction={k: v / n_samples for k, v in stats.items()},
    )
