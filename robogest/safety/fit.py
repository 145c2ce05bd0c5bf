"""Zero-lag preview: the whole-trajectory least-squares fit within the limits that :func:`track` then follows."""

from __future__ import annotations

from typing import Any

import numpy as np

from robogest.safety.limits import JointLimits, SafetyConfig
from robogest.safety.stages import _as_qt, _tracking_band

#: Weight of a rest frame's error in :func:`fit_within_limits` (1 elsewhere): the fit arrives at rest where the
#: tracker must.
REST_WEIGHT = 100.0


def fit_within_limits(
    targets: np.ndarray,
    limits: JointLimits,
    dt_s: float,
    q0: np.ndarray,
    *,
    margin_rad: float = SafetyConfig.margin_rad,
    rest_mask: np.ndarray | None = None,
    step0: np.ndarray | None = None,
) -> np.ndarray:
    """The trajectory closest to ``targets`` (weighted least squares) that keeps the position band, velocity and
    acceleration limits and starts still at ``q0``: the whole-trajectory counterpart of :func:`track`.

    A causal follower can only react, so where a stroke is faster than the robot allows it falls behind and its
    speed peak lands late (measured on the default generator's output for humanoid_xl430: 20-60 ms behind the
    IK targets, wrist-speed correlation 0.64-0.83; README, Safety). Knowing the whole trajectory, this starts such
    a move early and ends it late, centred on the target. One convex quadratic programme per joint (banded,
    solved by the interior-point solver ``piqp``); the result is feasible only to the solver's tolerance, so it
    is a *target* for :func:`track`, which makes every limit hold exactly.

    Parameters
    ----------
    targets : ndarray [shape=(T, J)], radians
        Frame 0 is ignored (it is ``q0``).
    limits : JointLimits
    dt_s : float, seconds
    q0 : ndarray [shape=(J,)], radians
        Start pose, standstill before it (as :func:`track` assumes).
    margin_rad : float, radians
    rest_mask : ndarray [shape=(T,)], bool, optional
        Frames whose target is rest (as for :func:`track`): their error weighs :data:`REST_WEIGHT` times more,
        so the fit arrives there, and they are returned as their targets, for :func:`track` to brake onto.
    step0 : ndarray [shape=(J,)], radians per frame, optional
        The step that led to ``q0`` (a continuation, as in :func:`track`); clipped to the velocity limit.

    Returns
    -------
    ndarray [shape=(T, J)], radians
        Frame 0 is ``q0`` and rest frames are their targets. A joint whose programme the solver does not solve
        keeps its targets (:func:`track` then follows them causally, as it does without this stage).
    """
    import scipy.sparse as sparse

    x = _as_qt(targets, "targets")
    q0 = np.asarray(q0, dtype=float)
    n_t, n_j = x.shape
    rest = np.zeros(n_t, bool) if rest_mask is None else np.asarray(rest_mask, dtype=bool)
    out = x.copy()
    if n_t:
        out[0] = q0
    n = n_t - 1  # unknowns: frames 1..T-1
    if n < 3:
        return np.where(rest[:, None], x, out)
    lo, hi = _tracking_band(limits, margin_rad)
    vstep = limits.v_max_rad_s * dt_s
    astep = limits.a_max_rad_s2 * dt_s * dt_s
    w = np.where(rest[1:], REST_WEIGHT, 1.0)
    s0 = np.zeros(n_j) if step0 is None else np.clip(np.asarray(step0, dtype=float), -vstep, vstep)
    ones = np.ones(n)
    d1 = sparse.diags([ones, -ones[1:]], [0, -1], shape=(n, n))  # row k: y[k+1] - y[k] (row 0: y[1], minus q0)
    d2 = sparse.diags([ones, -2 * ones[1:], ones[2:]], [0, -1, -2], shape=(n, n))  # second differences
    g = sparse.vstack([d1, d2], format="csc")
    p = sparse.diags(w, format="csc")
    for j in range(n_j):
        if limits.held_mask is not None and limits.held_mask[j]:  # band = its rest angle: track pins it, nothing to fit
            continue
        y = _fit_joint(p, g, -w * x[1:, j], q0[j], s0[j], vstep[j], astep[j], lo[j], hi[j])
        if y is not None:
            out[1:, j] = y
    return np.where(rest[:, None], x, out)


def _fit_joint(
    p: Any, g: Any, c: np.ndarray, q0: float, s0: float, vstep: float, astep: float, lo: float, hi: float
) -> np.ndarray | None:
    """One joint's programme ``min ½yᵀPy + cᵀy`` with ``|D1 y| ≤ V``, ``|D2 y| ≤ A`` (the rows that involve ``q0``
    and the step ``s0`` before it moved to the bounds) and the band widened to ``q0``; None if not solved."""
    import piqp

    n = c.size
    g_lo = np.r_[np.full(n, -vstep), np.full(n, -astep)]
    g_hi = -g_lo
    g_lo[0] += q0
    g_hi[0] += q0
    g_lo[n] += q0 + s0  # y[1] - 2 q0 + (q0 - step0)
    g_hi[n] += q0 + s0
    g_lo[n + 1] -= q0  # y[2] - 2 y[1] + q0
    g_hi[n + 1] -= q0
    solver = piqp.SparseSolver()
    solver.setup(p, c, None, None, g, g_lo, g_hi, np.full(n, min(lo, q0)), np.full(n, max(hi, q0)))
    if solver.solve() == piqp.PIQP_SOLVED and np.all(np.isfinite(solver.result.x)):
        return np.asarray(solver.result.x, dtype=float)
    return None
