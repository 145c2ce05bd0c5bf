"""Windowed hand-crafted motion features, Fréchet distances and diversity (after FID_k / FID_g of AIST++).

A learned FGD needs an auto-encoder trained on a large mocap corpus; these hand-crafted features need nothing
and still separate stiff, jittery and natural motion. Kinetic features describe how much each joint moves,
geometric features describe the poses (pairwise joint distances, invariant to where the speaker stands and
which way they face).
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import linalg
from scipy.spatial.distance import pdist

from robogest.errors import InputError

#: Default window and hop, seconds: about one gesture phrase, overlapping to get enough windows.
WINDOW_S = 2.0
HOP_S = 0.5


def sliding_windows(pos: np.ndarray, fps: float, window_s: float = WINDOW_S, hop_s: float = HOP_S) -> np.ndarray:
    """Overlapping windows of a motion.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, 3)], metres
    fps : float
    window_s, hop_s : float, seconds

    Returns
    -------
    ndarray [shape=(N, W, J, 3)]
        ``N = 1 + (T - W) // H`` windows (0 if the motion is shorter than one window).
    """
    pos = np.asarray(pos, dtype=np.float64)
    w = max(4, round(window_s * fps))
    h = max(1, round(hop_s * fps))
    if pos.shape[0] < w:
        return np.zeros((0, w, *pos.shape[1:]))
    starts = np.arange(0, pos.shape[0] - w + 1, h)
    return np.stack([pos[s : s + w] for s in starts])


def kinetic_features(window: np.ndarray, fps: float, up_axis: int = 1) -> np.ndarray:
    """Per-joint kinetic features of one window (as AIST++'s kinetic features).

    Per joint: mean horizontal kinetic energy ``½|v_h|²``, mean vertical kinetic energy ``½ v_up²`` (unit
    mass, m²/s²) and mean acceleration magnitude (energy expenditure, m/s²).

    Parameters
    ----------
    window : ndarray [shape=(W, J, 3)], metres
    fps : float
    up_axis : int
        Index of the vertical axis (Y up in the canonical skeleton).

    Returns
    -------
    ndarray [shape=(3 J,)]
    """
    v = np.diff(window, axis=0) * fps  # (W-1, J, 3)
    a = np.diff(window, n=2, axis=0) * fps**2
    horiz = [k for k in range(window.shape[-1]) if k != up_axis]
    ke_h = 0.5 * (v[..., horiz] ** 2).sum(-1).mean(0)
    ke_v = 0.5 * (v[..., up_axis] ** 2).mean(0)
    ee = np.linalg.norm(a, axis=-1).mean(0)
    return np.concatenate([ke_h, ke_v, ee])


def geometric_features(window: np.ndarray) -> np.ndarray:
    """Relational pose features of one window: mean and std over time of every pairwise joint distance.

    Parameters
    ----------
    window : ndarray [shape=(W, J, 3)], metres

    Returns
    -------
    ndarray [shape=(J (J - 1),)], metres
        ``J(J-1)/2`` means then ``J(J-1)/2`` standard deviations.
    """
    j = window.shape[1]
    iu = np.triu_indices(j, k=1)
    d = np.linalg.norm(window[:, :, None, :] - window[:, None, :, :], axis=-1)[:, iu[0], iu[1]]  # (W, P)
    return np.concatenate([d.mean(0), d.std(0)])


def window_features(
    pos: np.ndarray, fps: float, kind: str, window_s: float = WINDOW_S, hop_s: float = HOP_S
) -> np.ndarray:
    """Feature matrix ``(N, F)`` of all windows; ``kind`` is ``"kinetic"`` or ``"geometric"``."""
    wins = sliding_windows(pos, fps, window_s, hop_s)
    if len(wins) == 0:
        return np.zeros((0, 0))  # shorter than one window (e.g. half of a short take for the noise floor)
    if kind == "kinetic":
        return np.array([kinetic_features(w, fps) for w in wins]).reshape(len(wins), -1)
    if kind == "geometric":
        return np.array([geometric_features(w) for w in wins]).reshape(len(wins), -1)
    raise ValueError(f"unknown feature kind {kind!r}")


def normalize_pair(pred: np.ndarray, gt: np.ndarray, min_std: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """Z-score both feature sets with the ground truth's per-feature mean and std.

    Without this, features in m²/s² dwarf those in metres; features constant in the ground truth (fixed bone
    lengths) keep std 1 so they neither explode nor vanish.
    """
    mu = gt.mean(axis=0)
    sd = gt.std(axis=0)
    sd = np.where(sd > min_std, sd, 1.0)
    return (pred - mu) / sd, (gt - mu) / sd


def frechet_distance(feat_a: np.ndarray, feat_b: np.ndarray, eps: float = 1e-6) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets.

    ``|μ_a - μ_b|² + tr(Σ_a + Σ_b - 2 (Σ_a Σ_b)^½)``. Numerical care as in pytorch-fid: if ``sqrtm`` of
    the (often rank-deficient: few windows, many features) product is singular or not finite, retry with
    ``eps`` added to both diagonals; a small imaginary part from round-off is dropped; the result is clipped
    at 0.

    Parameters
    ----------
    feat_a : ndarray [shape=(N_a, F)]
    feat_b : ndarray [shape=(N_b, F)]
        At least 2 rows each.

    Returns
    -------
    float
        In squared feature units.
    """
    a = np.asarray(feat_a, dtype=np.float64)
    b = np.asarray(feat_b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise InputError(f"feature sets must be (N, F) with equal F, got {a.shape} and {b.shape}")
    if a.shape[0] < 2 or b.shape[0] < 2:
        raise InputError(f"Fréchet distance needs at least 2 windows per set, got {a.shape[0]} and {b.shape[0]}")
    mu_a, mu_b = a.mean(0), b.mean(0)
    s_a = np.atleast_2d(np.cov(a, rowvar=False))
    s_b = np.atleast_2d(np.cov(b, rowvar=False))
    with warnings.catch_warnings():
        warnings.simplefilter("error", linalg.LinAlgWarning)
        try:
            covmean = linalg.sqrtm(s_a @ s_b)
        except linalg.LinAlgWarning:
            covmean = np.full_like(s_a, np.nan)
    if not np.isfinite(covmean).all():
        off = np.eye(s_a.shape[0]) * eps
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", linalg.LinAlgWarning)
            covmean = linalg.sqrtm((s_a + off) @ (s_b + off))
    covmean = np.real(covmean)
    diff = mu_a - mu_b
    fd = float(diff @ diff + np.trace(s_a) + np.trace(s_b) - 2.0 * np.trace(covmean))
    return max(fd, 0.0)


def feature_distances(
    pred_pos: np.ndarray, gt_pos: np.ndarray, fps: float, window_s: float = WINDOW_S, hop_s: float = HOP_S
) -> dict:
    """FD_k and FD_g (kinetic / geometric Fréchet distances on gt-normalised features) and diversities.

    Returns
    -------
    dict
        ``fd_kinetic``, ``fd_geometric`` (NaN if either motion has < 2 windows), ``diversity_kinetic``,
        ``diversity_geometric`` (pred) and ``gt_diversity_*`` for reference, ``n_windows_pred``,
        ``n_windows_gt``.
    """
    out: dict = {}
    for kind in ("kinetic", "geometric"):
        fp = window_features(pred_pos, fps, kind, window_s, hop_s)
        fg = window_features(gt_pos, fps, kind, window_s, hop_s)
        out["n_windows_pred"], out["n_windows_gt"] = len(fp), len(fg)
        if len(fp) < 2 or len(fg) < 2:
            out[f"fd_{kind}"] = out[f"diversity_{kind}"] = out[f"gt_diversity_{kind}"] = float("nan")
            continue
        np_, ng = normalize_pair(fp, fg)
        out[f"fd_{kind}"] = frechet_distance(np_, ng)
        out[f"diversity_{kind}"] = diversity(np_)
        out[f"gt_diversity_{kind}"] = diversity(ng)
    return out


def diversity(features: np.ndarray) -> float:
    """Mean Euclidean distance over all pairs of rows ``(N, F)``; NaN with fewer than 2 rows.

    Measures how different the generated windows are from each other: a generator that repeats one gesture
    scores near 0.
    """
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[0] < 2:
        return float("nan")
    return float(pdist(f).mean())


def lexeme_entropy(lexeme_ids: np.ndarray, n_lexemes: int | None = None) -> dict:
    """Entropy of gesture-lexeme usage (Rhythmic Gesticulator eq. 23), natural log.

    Parameters
    ----------
    lexeme_ids : ndarray [shape=(N,)], int
        Lexeme id of each generated motion block.
    n_lexemes : int, optional
        Lexicon size N_s; if given, also the entropy divided by ``log N_s`` (1 = all lexemes used equally).

    Returns
    -------
    dict
        ``entropy_nats`` and ``normalized`` (NaN without ``n_lexemes`` or with N_s ≤ 1).
    """
    ids = np.asarray(lexeme_ids).ravel()
    if ids.size == 0:
        return {"entropy_nats": float("nan"), "normalized": float("nan")}
    _, counts = np.unique(ids, return_counts=True)
    p = counts / counts.sum()
    h = float(-(p * np.log(p)).sum())
    norm = h / np.log(n_lexemes) if n_lexemes is not None and n_lexemes > 1 else float("nan")
    return {"entropy_nats": h, "normalized": float(norm)}
