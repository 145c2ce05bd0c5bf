"""Metrics on robot command trajectories (joint angles): limits, jerk, settling in silence, tracking.

Finite differences here match how the commands are played: one sample per control tick at ``fps``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robogest.errors import InputError
from robogest.eval.kinematics import spans_to_mask, truncate_pair


def _check_q(q: np.ndarray, name: str = "q_rad") -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2:
        raise InputError(f"{name} must be (T, J) joint angles, got shape {q.shape}")
    if not np.isfinite(q).all():
        raise InputError(f"{name} contains NaN or infinite values")
    return q


def _excess(values: np.ndarray, lo: np.ndarray | None, hi: np.ndarray, names: Sequence[str], tol: float) -> dict:
    over = values - hi
    if lo is not None:
        over = np.maximum(over, lo - values)
    bad = over > tol
    worst = float(over.max()) if over.size else 0.0
    per_joint = {n: int(c) for n, c in zip(names, bad.sum(axis=0), strict=True) if c}
    return {"count": int(bad.sum()), "max_excess": max(worst, 0.0), "per_joint": per_joint}


def limit_violations(
    q_rad: np.ndarray,
    fps: float,
    q_min_rad: np.ndarray,
    q_max_rad: np.ndarray,
    v_max_rad_s: np.ndarray,
    a_max_rad_s2: np.ndarray,
    joint_names: Sequence[str] | None = None,
    rel_tol: float = 1e-6,
) -> dict:
    """Count samples outside position, velocity and acceleration limits.

    Parameters
    ----------
    q_rad : ndarray [shape=(T, J)], radians
    fps : float
    q_min_rad, q_max_rad : ndarray [shape=(J,)], radians
    v_max_rad_s : ndarray [shape=(J,)], rad/s
        Applied to ``|Δq| · fps``.
    a_max_rad_s2 : ndarray [shape=(J,)], rad/s²
        Applied to ``|Δ²q| · fps²``.
    joint_names : sequence of str, optional
    rel_tol : float
        Excess below ``rel_tol × limit`` (float round-off of a trajectory made exactly at the limit) is not a
        violation.

    Returns
    -------
    dict
        ``position``, ``velocity``, ``acceleration``: each ``count`` (samples × joints over the limit),
        ``max_excess`` (rad, rad/s, rad/s²; 0 if none) and ``per_joint`` counts; ``total``.
    """
    q = _check_q(q_rad)
    names = [str(j) for j in range(q.shape[1])] if joint_names is None else list(joint_names)
    lo, hi = np.asarray(q_min_rad, float), np.asarray(q_max_rad, float)
    vmax, amax = np.abs(np.asarray(v_max_rad_s, float)), np.abs(np.asarray(a_max_rad_s2, float))
    scale = max(1.0, float(np.abs(np.concatenate([lo, hi])).max(initial=0)))
    out = {"position": _excess(q, lo, hi, names, rel_tol * scale)}
    v = np.abs(np.diff(q, axis=0)) * fps
    a = np.abs(np.diff(q, n=2, axis=0)) * fps**2
    out["velocity"] = _excess(v, None, vmax, names, rel_tol * float(vmax.max(initial=1)))
    out["acceleration"] = _excess(a, None, amax, names, rel_tol * float(amax.max(initial=1)))
    out["total"] = sum(out[k]["count"] for k in ("position", "velocity", "acceleration"))
    return out


def joint_jerk(q_rad: np.ndarray, fps: float, joint_names: Sequence[str] | None = None) -> dict:
    """Mean and max absolute joint jerk, rad/s³, overall and per joint (servo wear and audible noise)."""
    q = _check_q(q_rad)
    if q.shape[0] < 4:
        return {"mean_rad_s3": float("nan"), "max_rad_s3": float("nan"), "per_joint_mean_rad_s3": {}}
    names = [str(j) for j in range(q.shape[1])] if joint_names is None else list(joint_names)
    j = np.abs(np.diff(q, n=3, axis=0)) * fps**3
    return {
        "mean_rad_s3": float(j.mean()),
        "max_rad_s3": float(j.max()),
        "per_joint_mean_rad_s3": dict(zip(names, j.mean(axis=0).tolist(), strict=True)),
    }


def mask_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` index ranges of the True runs of a boolean ``(T,)`` mask."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def time_to_rest(
    q_rad: np.ndarray,
    fps: float,
    silent: np.ndarray | Sequence[tuple[float, float]],
    rest_q_rad: np.ndarray,
    tol_rad: float = 0.02,
) -> dict:
    """How long the robot takes, in each silent period, to come within ``tol_rad`` of rest on every joint.

    Parameters
    ----------
    q_rad : ndarray [shape=(T, J)], radians
    fps : float
    silent : ndarray [shape=(T,)] of bool, or sequence of (start_s, end_s)
    rest_q_rad : ndarray [shape=(J,)], radians
    tol_rad : float
        Max-abs deviation from rest counted as "at rest".

    Returns
    -------
    dict
        ``per_span``: list of dicts with ``start_s``, ``duration_s``, ``time_to_rest_s`` (None if rest was
        never reached within the span); ``mean_s`` and ``max_s`` over reached spans (NaN if none);
        ``n_spans``, ``n_unreached``.
    """
    q = _check_q(q_rad)
    n = q.shape[0]
    if isinstance(silent, np.ndarray) and silent.dtype == bool:
        mask = np.zeros(n, dtype=bool)
        mask[: min(n, silent.shape[0])] = silent[:n]
    else:
        mask = spans_to_mask(list(silent), n, fps)
    at_rest = np.abs(q - np.asarray(rest_q_rad, float)).max(axis=1) <= tol_rad
    per_span, reached = [], []
    for a, b in mask_runs(mask):
        hit = np.flatnonzero(at_rest[a:b])
        t = float(hit[0] / fps) if hit.size else None
        per_span.append({"start_s": a / fps, "duration_s": (b - a) / fps, "time_to_rest_s": t})
        if t is not None:
            reached.append(t)
    return {
        "per_span": per_span,
        "mean_s": float(np.mean(reached)) if reached else float("nan"),
        "max_s": float(np.max(reached)) if reached else float("nan"),
        "n_spans": len(per_span),
        "n_unreached": len(per_span) - len(reached),
    }


def tracking_error(q_cmd_rad: np.ndarray, q_achieved_rad: np.ndarray, joint_names: Sequence[str] | None = None) -> dict:
    """Commanded vs achieved (simulated or measured) joint angles; truncated to the shorter.

    Returns
    -------
    dict
        ``rms_rad``, ``max_abs_rad``, ``per_joint_rms_rad``, ``n_frames``, ``dropped_frames``.
    """
    c, a = _check_q(q_cmd_rad, "commanded"), _check_q(q_achieved_rad, "achieved")
    if c.shape[1] != a.shape[1]:
        raise InputError(f"commanded and achieved have different joint counts: {c.shape[1]} vs {a.shape[1]}")
    c, a, dropped = truncate_pair(c, a)
    names = [str(j) for j in range(c.shape[1])] if joint_names is None else list(joint_names)
    e = a - c
    return {
        "rms_rad": float(np.sqrt(np.mean(e**2))) if e.size else float("nan"),
        "max_abs_rad": float(np.abs(e).max()) if e.size else float("nan"),
        "per_joint_rms_rad": dict(zip(names, np.sqrt(np.mean(e**2, axis=0)).tolist(), strict=True)),
        "n_frames": len(c),
        "dropped_frames": dropped,
    }
