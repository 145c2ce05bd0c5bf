"""The safety stages, each a pure function on a whole ``(T, J)`` trajectory.

Discrete-time conventions used throughout (``dt = 1/fps``):

* step ``d[k] = q[k] − q[k−1]``; the velocity limit is ``|d[k]| ≤ V = v_max·dt``;
* the acceleration limit is ``|d[k] − d[k−1]| ≤ A = a_max·dt²``, with the robot at standstill before frame 0
  (``d[0] = 0``), so the first step is at most ``A`` as well.

The clamp/smooth/velocity stages only shape the *targets*; :func:`track` is the stage that makes every
constraint hold at once, exactly (to floating-point rounding), because it brakes in discrete time.
"""

from __future__ import annotations

import math

import numpy as np

from robogest.errors import InputError, SafetyError
from robogest.safety.limits import JointLimits, SafetyConfig, opencv_sigma
from robogest.safety.rest import long_silent_spans as long_silent_spans  # where the session tests look for it

#: Slack for comparing constraint values after floating-point arithmetic (radians).
TOL = 1e-9


def _as_qt(q: np.ndarray, name: str = "q") -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        raise InputError(f"{name} must have shape (T, J), got {q.shape}")
    return q


def clamp_positions(q: np.ndarray, limits: JointLimits, margin_rad: float) -> np.ndarray:
    """Clip every sample into ``[q_min + margin, q_max − margin]`` (the midpoint for a range under ``2·margin``).

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
    limits : JointLimits
    margin_rad : float, radians

    Returns
    -------
    ndarray [shape=(T, J)], radians
    """
    lo, hi = limits.band(margin_rad)
    return np.asarray(np.clip(_as_qt(q), lo, hi), dtype=float)


def gaussian_kernel(kernel: int, sigma: float | None = None) -> np.ndarray:
    """Normalised Gaussian weights ``(kernel,)``; sigma in frames, None for :func:`opencv_sigma`."""
    if kernel < 1 or kernel % 2 == 0:
        raise InputError(f"smoothing kernel must be an odd integer ≥ 1, got {kernel}")
    sigma = opencv_sigma(kernel) if sigma is None else float(sigma)
    if not sigma > 0:
        raise InputError(f"smoothing sigma must be > 0 frames, got {sigma}")
    r = kernel // 2
    w = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    return np.asarray(w / w.sum(), dtype=float)


def smooth(q: np.ndarray, kernel: int = 5, sigma: float | None = None) -> np.ndarray:
    """Gaussian smoothing along time, edges padded with the end samples.

    Edge padding (not zeros) keeps the first/last sample from being pulled towards 0 rad, and every output is
    a convex combination of inputs, so samples inside a position band stay inside it.

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
    kernel : int
        Odd kernel size in frames; 1 returns a copy.
    sigma : float or None, frames
        None uses OpenCV's rule (1.1 frames for a kernel of 5).

    Returns
    -------
    ndarray [shape=(T, J)], radians
    """
    q = _as_qt(q)
    w = gaussian_kernel(kernel, sigma)
    if kernel == 1 or q.shape[0] == 0:
        return np.asarray(q.copy(), dtype=float)
    r = kernel // 2
    padded = np.pad(q, ((r, r), (0, 0)), mode="edge")
    t = q.shape[0]
    out = np.zeros_like(q)
    for i, wi in enumerate(w):
        out += wi * padded[i : i + t]
    return out


def clamp_velocity(q: np.ndarray, v_max: np.ndarray, dt_s: float) -> np.ndarray:
    """Rate limiter: follow ``q`` from ``q[0]`` with every step ``|Δq| ≤ v_max·dt``.

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
    v_max : ndarray [shape=(J,)], rad/s
    dt_s : float, seconds

    Returns
    -------
    ndarray [shape=(T, J)], radians
    """
    q = _as_qt(q)
    vstep = np.asarray(v_max, dtype=float) * dt_s
    out = q.copy()
    if q.shape[0] < 2:
        return np.asarray(out, dtype=float)
    d = np.diff(q, axis=0)
    if np.all(np.abs(d) <= vstep):  # nothing to do: keep the input bit-exact
        return np.asarray(out, dtype=float)
    p = out[0].copy()
    neg = -vstep
    for k in range(1, q.shape[0]):
        p = p + np.minimum(np.maximum(q[k] - p, neg), vstep)
        out[k] = p
    return np.asarray(out, dtype=float)


def _brake_step(dist: np.ndarray, a_step: np.ndarray) -> np.ndarray:
    """Largest step ``s ≥ 0`` after which the joint can still stop within ``dist ≥ 0``.

    Stopping from step ``s`` with decrements of ``A`` covers ``f(s) = Σ_{i≥0} max(s − iA, 0)`` including ``s``
    itself; this is ``f⁻¹(dist)``: with ``m = ⌊(√(1 + 8·dist/A) − 1)/2⌋`` (whole decrements that fit),
    ``s = (dist + A·m(m+1)/2) / (m+1)``. The discrete counterpart of ``v ≤ √(2·a·distance)``.

    Parameters
    ----------
    dist : ndarray, radians (≥ 0)
    a_step : ndarray, radians per frame² (``a_max·dt²``), broadcastable to ``dist``

    Returns
    -------
    ndarray, radians per frame
    """
    m = np.floor(0.5 * (np.sqrt(1.0 + 8.0 * dist / a_step) - 1.0))
    m1 = m + 1.0
    return np.asarray((dist + 0.5 * a_step * m * m1) / m1, dtype=float)


def _tracking_band(limits: JointLimits, margin_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Margin band widened to include the rest pose (rest is declared safe even if it sits in the margin)."""
    lo, hi = limits.band(margin_rad)
    return np.minimum(lo, limits.rest_q_rad), np.maximum(hi, limits.rest_q_rad)


def _run_tracker(
    x: np.ndarray,
    w: np.ndarray,
    p: np.ndarray,
    s: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    vstep: np.ndarray,
    astep: np.ndarray,
    out: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Advance the tracker over rows ``x[0..n)`` writing ``out[0..n)``; returns the final ``(p, s)``.

    Per frame and joint, the next step ``s'`` is the desired step (feed-forward ``w`` plus braking towards
    the target) clipped to, in increasing priority: the position band (discrete braking bound towards each
    edge), ``|s'| ≤ V``, and ``|s' − s| ≤ A``. The band bound is always compatible with ``s' = s − A``
    (proof by induction in the module docs of :func:`track`), so the last clip costs nothing but rounding.
    """
    j = p.size
    buf = np.empty((3, j))
    a3 = np.broadcast_to(astep, (3, j))
    neg_v = -vstep
    for k in range(x.shape[0]):
        xk = x[k]
        wk = w[k]
        err = xk - p  # error to this frame's target before the step
        rel = err - wk  # error relative to a target moving with step wk
        np.abs(rel, out=buf[0])
        np.subtract(hi, p, out=buf[1])
        np.subtract(p, lo, out=buf[2])
        np.maximum(buf, 0.0, out=buf)
        g = _brake_step(buf, a3)
        s_new = wk + np.copysign(g[0], rel)
        s_new = np.minimum(np.maximum(s_new, np.maximum(-g[2], neg_v)), np.minimum(g[1], vstep))
        s_new = np.minimum(np.maximum(s_new, s - astep), s + astep)
        p = np.where(s_new == err, xk, p + s_new)  # land exactly on the target when the step reaches it
        out[k] = p
        s = s_new
    return p, s


def rest_reach_time_s(
    q_from: np.ndarray | JointLimits | None, limits: JointLimits | None = None, fps: float | None = None
) -> float:
    """Upper bound (seconds) on the time :func:`track` needs to be at rest and stopped.

    Worst case per joint: moving *away* from rest at ``v_max``; brake (``v/a``, adding ``v²/2a`` of distance),
    then a rest-to-rest move over ``D = |q_from − rest| + v²/2a`` (``2√(D/a)`` or ``D/v + v/a``). With ``fps``
    three frames are added for discretisation (a braking frame, a landing frame, one zero-velocity frame).

    Parameters
    ----------
    q_from : ndarray [shape=(J,)], radians, or None
        Pose when the robot is told to go to rest; None takes the worst pose within the limits.
        ``rest_reach_time_s(limits)`` (limits as the only argument) is the same as ``q_from=None``.
    limits : JointLimits
    fps : float or None, frames/s
        Frame rate for the frame-exact bound; None gives the continuous-time bound.

    Returns
    -------
    float, seconds
        Counted from the first frame whose target is rest: every frame this much later or more is at rest.
    """
    if isinstance(q_from, JointLimits) and limits is None:
        q_from, limits = None, q_from
    if limits is None:
        raise InputError("rest_reach_time_s: limits are required")
    v = limits.v_max_rad_s
    a = limits.a_max_rad_s2
    rest = limits.rest_q_rad
    if q_from is None:
        dist = np.maximum(limits.q_max_rad - rest, rest - limits.q_min_rad)
    else:
        dist = np.abs(np.asarray(q_from, dtype=float) - rest)
    d = dist + v * v / (2.0 * a)
    move = np.where(d <= v * v / a, 2.0 * np.sqrt(d / a), d / v + v / a)
    t = float(np.max(v / a + move))
    return t + (3.0 / fps if fps else 0.0)


def track(
    targets: np.ndarray,
    limits: JointLimits,
    dt_s: float,
    q0: np.ndarray,
    *,
    margin_rad: float = SafetyConfig.margin_rad,
    rest_mask: np.ndarray | None = None,
    settle: bool = False,
    step0: np.ndarray | None = None,
) -> np.ndarray:
    """Follow ``targets`` so that position, velocity and acceleration limits all hold at once.

    Output frame 0 is ``q0`` (the robot is assumed still there, or moving by ``step0`` per frame); each later
    frame takes the step that best follows the target subject to ``|d| ≤ v_max·dt``, ``|Δd| ≤ a_max·dt²`` and
    the position band
    ``[q_min + margin, q_max − margin]`` widened to include rest. Braking is discrete: the step towards an
    edge is at most :func:`_brake_step` of the distance, which guarantees that decelerating by ``A`` per
    frame stops inside the band. If that bound held at ``(p, s)``, then ``s − A`` (or 0) satisfies it at
    the next frame, so the acceleration clip never has to break it (induction); the constraints therefore
    hold exactly up to rounding, which is checked on the result. A ``q0`` inside the margin (but within the
    hard limits) is left inwards only. A continuation (``step0``) that arrives moving towards an edge faster than
    the bound allows brakes at ``A`` from its first frame and may enter the margin by at most its stopping
    distance (checked, as the hard limits are): a streamed plan continues the frames already played, which
    were made before it.

    Parameters
    ----------
    targets : ndarray [shape=(T, J)], radians
        Desired poses; frame 0 is ignored (it is ``q0``).
    limits : JointLimits
    dt_s : float, seconds
    q0 : ndarray [shape=(J,)], radians
        Current pose, within ``[q_min, q_max]``.
    margin_rad : float, radians
    rest_mask : ndarray [shape=(T,)], bool, optional
        Frames whose target is stationary (rest): no velocity feed-forward there, so the robot brakes
        exactly onto the target and stays.
    settle : bool
        Extend the output past ``T`` until it is at ``limits.rest_q_rad`` with zero velocity.
    step0 : ndarray [shape=(J,)], radians per frame, optional
        The step that led to ``q0`` (a continuation, e.g. of a streamed plan); clipped to the velocity limit.

    Returns
    -------
    ndarray [shape=(T', J)], radians
        ``T' = max(T, 1)``, or more with ``settle``.

    Raises
    ------
    SafetyError
        If the result would break a limit (a bug guard, not expected) or cannot settle.
    """
    out, p, s = track_run(targets, limits, dt_s, q0, margin_rad=margin_rad, rest_mask=rest_mask, step0=step0)
    if settle:
        out = np.vstack([out, settle_tail(out[-2:], p, s, limits, dt_s, margin_rad)])
    lo_ok, hi_ok, s0 = continuation_bounds(limits, dt_s, np.asarray(q0, dtype=float), margin_rad, step0)
    check_limits(out, limits, dt_s, lo_ok, hi_ok, s0)  # the hard limits always
    return out


def track_run(
    targets: np.ndarray,
    limits: JointLimits,
    dt_s: float,
    q0: np.ndarray,
    *,
    margin_rad: float = SafetyConfig.margin_rad,
    rest_mask: np.ndarray | None = None,
    step0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`track` without settling or the final check: ``(out (max(T, 1), J), p (J,), s (J,))``, the frames and
    the tracker's last position and step (radians, radians per frame), from which a later call or
    :func:`settle_tail` continues exactly."""
    x = _as_qt(targets, "targets")
    q0 = np.asarray(q0, dtype=float)
    n_t, n_j = x.shape
    if n_j != limits.n_joints or q0.shape != (n_j,):
        raise InputError(f"track: targets {x.shape} / q0 {q0.shape} do not match {limits.n_joints} joints")
    lo, hi = _tracking_band(limits, margin_rad)
    vstep = limits.v_max_rad_s * dt_s
    astep = limits.a_max_rad_s2 * dt_s * dt_s
    x = np.clip(x, lo, hi)
    w = np.zeros_like(x)
    if n_t > 1:
        w[1:] = np.clip(np.diff(x, axis=0), -vstep, vstep)
    if rest_mask is not None:
        w[np.asarray(rest_mask, dtype=bool)] = 0.0
    out = np.empty((max(n_t, 1), n_j))
    out[0] = q0
    s0 = np.zeros(n_j) if step0 is None else np.clip(np.asarray(step0, dtype=float), -vstep, vstep)
    p, s = _run_tracker(x[1:], w[1:], q0.copy(), s0.copy(), lo, hi, vstep, astep, out[1:])
    return out, p, s


def continuation_bounds(
    limits: JointLimits, dt_s: float, q0: np.ndarray, margin_rad: float, step0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(lo, hi, step0)`` that :func:`check_limits` holds a tracked run from ``q0`` to: the margin band widened to
    rest and ``q0`` (left inwards only) and, for a continuation arriving towards an edge (``step0``, clipped to
    the velocity limit as the tracker clips it), by its stopping distance: it brakes at ``A`` from frame 1."""
    lo, hi = _tracking_band(limits, margin_rad)
    lo_ok, hi_ok = np.minimum(lo, q0), np.maximum(hi, q0)
    if step0 is None:
        return lo_ok, hi_ok, None
    vstep = limits.v_max_rad_s * dt_s
    s0 = np.clip(np.asarray(step0, dtype=float), -vstep, vstep)
    reach = _stop_distance(np.abs(s0), limits.a_max_rad_s2 * dt_s * dt_s)  # (J,) radians travelled while braking
    lo_ok = np.where(s0 < 0, np.minimum(lo_ok, q0 - reach), lo_ok)
    hi_ok = np.where(s0 > 0, np.maximum(hi_ok, q0 + reach), hi_ok)
    return lo_ok, hi_ok, s0


def _stop_distance(step: np.ndarray, a_step: np.ndarray) -> np.ndarray:
    """``f(s) = Σ_{i≥0} max(s − iA, 0)``: how far a joint moving ``step ≥ 0`` per frame travels (that step
    included) while braking by ``A`` per frame (the inverse of :func:`_brake_step`)."""
    a = np.broadcast_to(a_step, step.shape)
    m = np.floor(step / a)
    return np.asarray((m + 1) * step - a * m * (m + 1) / 2, dtype=float)


def settle_tail(
    last: np.ndarray, p: np.ndarray, s: np.ndarray, limits: JointLimits, dt_s: float, margin_rad: float
) -> np.ndarray:
    """Frames ``(N, J)`` to append after ``last`` (the last one or two frames, ``(≤2, J)``) that bring the tracker,
    at position ``p`` moving ``s`` per frame, to ``limits.rest_q_rad`` with zero velocity (none if it is there)."""
    rest = limits.rest_q_rad
    at_rest = np.all(last == rest, axis=1)
    if at_rest[-1] and (last.shape[0] == 1 or at_rest[-2]):
        return np.asarray(last[:0].copy(), dtype=float)
    lo, hi = _tracking_band(limits, margin_rad)
    n = math.ceil(rest_reach_time_s(p, limits, 1.0 / dt_s) / dt_s) + 2
    ext = np.empty((n, last.shape[1]))
    x = np.broadcast_to(rest, ext.shape)
    vstep, astep = limits.v_max_rad_s * dt_s, limits.a_max_rad_s2 * dt_s * dt_s
    _run_tracker(x, np.zeros_like(ext), p, s, lo, hi, vstep, astep, ext)
    both = np.vstack([last[-1:], ext])
    done = np.flatnonzero(np.all(both[1:] == rest, axis=1) & np.all(both[:-1] == rest, axis=1))
    if done.size == 0:
        raise SafetyError("safety: the robot could not be brought to rest within the computed bound (bug)")
    return ext[: done[0] + 1]


def check_limits(
    q: np.ndarray,
    limits: JointLimits,
    dt_s: float,
    lo: np.ndarray,
    hi: np.ndarray,
    d0: np.ndarray | None = None,
    frame0: int = 0,
) -> None:
    """Raise :class:`SafetyError` unless ``q`` is finite, within ``[lo, hi]``, ``|d| ≤ V`` and ``|Δd| ≤ A`` (+ ``TOL``).

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
        Starting at standstill (the first step counts against ``A``), or moving by ``d0`` per frame.
    limits : JointLimits
    dt_s : float, seconds
    lo, hi : ndarray [shape=(J,)], radians
    d0 : ndarray [shape=(J,)], radians per frame, optional
        The step that led to ``q[0]``.
    frame0 : int
        Frame number of ``q[0]`` in the message (a chunk of a longer trajectory).
    """
    if not np.all(np.isfinite(q)):  # NaN compares False with every bound below
        raise SafetyError("safety: command trajectory holds NaN or infinite angles (internal check)")
    pos_bad = (q < lo - TOL) | (q > hi + TOL) | (q < limits.q_min_rad - TOL) | (q > limits.q_max_rad + TOL)  # (T, J)
    d = np.diff(q, axis=0, prepend=q[:1] if d0 is None else q[:1] - d0)  # (T, J) rad per frame
    vel_bad = np.abs(d) > limits.v_max_rad_s * dt_s + TOL
    dd = np.diff(d, axis=0)  # (T-1, J)
    acc_bad = np.abs(dd) > limits.a_max_rad_s2 * dt_s * dt_s + TOL
    if pos_bad.any() or vel_bad.any() or acc_bad.any():
        what = [n for n, b in (("position", pos_bad), ("velocity", vel_bad), ("acceleration", acc_bad)) if b.any()]
        if pos_bad.any():  # the first offending frame and joint of the first kind broken, for the message
            t, j = np.argwhere(pos_bad)[0]
            low, high = max(lo[j], limits.q_min_rad[j]), min(hi[j], limits.q_max_rad[j])
            first = f"{q[t, j]:.4f} rad outside [{low:.4f}, {high:.4f}]"
        elif vel_bad.any():
            t, j = np.argwhere(vel_bad)[0]
            first = f"{abs(d[t, j]) / dt_s:.3f} rad/s against {limits.v_max_rad_s[j]:g}"
        else:
            t, j = np.argwhere(acc_bad)[0]
            t += 1
            first = f"{abs(dd[t - 1, j]) / dt_s**2:.2f} rad/s² against {limits.a_max_rad_s2[j]:g}"
        name = limits.names[j] if len(limits.names) > j else f"joint {j}"
        raise SafetyError(
            f"safety: command trajectory breaks the {'/'.join(what)} limit (internal check); first: {name} at frame "
            f"{t + frame0} ({(t + frame0) * dt_s:.2f} s): {first}"
        )


def limit_acceleration(
    q: np.ndarray,
    limits: JointLimits,
    dt_s: float,
    q0: np.ndarray | None = None,
    *,
    margin_rad: float = SafetyConfig.margin_rad,
) -> np.ndarray:
    """Acceleration-, velocity- and position-limited version of ``q``: :func:`track` with ``q`` as targets.

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
    limits : JointLimits
    dt_s : float, seconds
    q0 : ndarray [shape=(J,)], radians, optional
        Start pose (at standstill); default ``q[0]`` clipped into the band.
    margin_rad : float, radians

    Returns
    -------
    ndarray [shape=(T, J)], radians
    """
    q = _as_qt(q)
    if q0 is None:
        if q.shape[0] == 0:
            return np.asarray(q.copy(), dtype=float)
        lo, hi = _tracking_band(limits, margin_rad)
        q0 = np.clip(q[0], lo, hi)
    return track(q, limits, dt_s, q0, margin_rad=margin_rad)[: q.shape[0]]
