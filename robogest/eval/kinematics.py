"""Kinematic statistics of joint-position motion (Gesticulator §5.1, Rhythmic Gesticulator §7.3.2).

Every function takes plain arrays so that generators, importers and tests can share them. Derivatives are
plain finite differences: they are what the published numbers use, and the bias on a sinusoid of angular
frequency ω is only ``(ω·dt)²/12`` (acceleration) or ``(ω·dt)²/8`` (jerk), under 1 % for gestures below
~2 Hz at 30 fps.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robogest.errors import InputError

#: Metres to centimetres: the papers report cm/s, cm/s², cm/s³.
M_TO_CM = 100.0
#: Metres to millimetres (MAJE/MAD are reported in mm, mm/s²).
M_TO_MM = 1000.0


def _check_pos(pos: np.ndarray, fps: float, min_frames: int = 1, name: str = "pos") -> np.ndarray:
    pos = np.asarray(pos, dtype=np.float64)
    if pos.ndim != 3:
        raise InputError(f"{name} must be (T, J, D) joint positions, got shape {pos.shape}")
    if pos.shape[0] < min_frames:
        raise InputError(f"{name} needs at least {min_frames} frames, got {pos.shape[0]}")
    if not fps > 0:
        raise InputError(f"frame rate must be positive, got {fps}")
    if not np.isfinite(pos).all():
        raise InputError(f"{name} contains NaN or infinite values")
    return pos


def derivative(pos: np.ndarray, fps: float, order: int) -> np.ndarray:
    """Finite-difference time derivative.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, D)]
        Positions (any unit).
    fps : float
        Frames per second.
    order : int
        1 velocity, 2 acceleration, 3 jerk.

    Returns
    -------
    ndarray [shape=(T - order, J, D)]
        Derivative in unit/s**order.
    """
    pos = _check_pos(pos, fps, order + 1)
    return np.diff(pos, n=order, axis=0) * fps**order


def joint_speed(pos: np.ndarray, fps: float) -> np.ndarray:
    """Per-joint speed ``(T-1, J)`` in unit/s (Euclidean norm of the velocity)."""
    speed: np.ndarray = np.linalg.norm(derivative(pos, fps, 1), axis=-1)
    return speed


def motion_statistics(pos: np.ndarray, fps: float, joint_names: Sequence[str] | None = None) -> dict:
    """Mean acceleration and jerk magnitudes, per joint and overall.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, 3)], metres
    fps : float
    joint_names : sequence of str, optional
        Keys of the per-joint dictionaries (default ``"0"``, ``"1"``, ...).

    Returns
    -------
    dict
        ``acceleration_cm_s2`` and ``jerk_cm_s3`` (overall means of the norm over frames and joints),
        ``per_joint_acceleration_cm_s2`` and ``per_joint_jerk_cm_s3`` (dicts by joint name).
    """
    pos = _check_pos(pos, fps, 4)
    names = [str(j) for j in range(pos.shape[1])] if joint_names is None else list(joint_names)
    acc = np.linalg.norm(derivative(pos, fps, 2), axis=-1) * M_TO_CM  # (T-2, J)
    jerk = np.linalg.norm(derivative(pos, fps, 3), axis=-1) * M_TO_CM  # (T-3, J)
    return {
        "acceleration_cm_s2": float(acc.mean()),
        "jerk_cm_s3": float(jerk.mean()),
        "per_joint_acceleration_cm_s2": dict(zip(names, acc.mean(axis=0).tolist(), strict=True)),
        "per_joint_jerk_cm_s3": dict(zip(names, jerk.mean(axis=0).tolist(), strict=True)),
    }


#: Joint sets on which the papers compute their motion statistics, on the canonical skeleton. Root translation
#: is removed first (positions relative to the pelvis) because every paper fixes or drops the root.
#:
#: - ``gesticulator``: Gesticulator §5.1 averages acceleration and jerk "over all frames for all 14 3D joints
#:   (except for the hips, which were fixed)", the Trinity upper body; here the 13 canonical upper-body joints
#:   below the pelvis that are not direction-only leaves (``nose``, ``l_hand``, ``r_hand``).
#: - ``s2ag``: S2AG §5.2 (and the Rhythmic Gesticulator on TED) use the 10 TED Gesture joints: spine, neck, nose,
#:   head, shoulders, elbows, wrists (TED's spine is the skeleton's fixed anchor; the canonical ``spine`` is the
#:   nearest joint).
PAPER_JOINT_SETS: dict[str, tuple[str, ...]] = {
    "gesticulator": (
        "spine", "spine1", "spine2", "neck", "head", "l_collar", "l_shoulder", "l_elbow", "l_wrist",
        "r_collar", "r_shoulder", "r_elbow", "r_wrist",
    ),
    "s2ag": ("spine", "neck", "nose", "head", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist"),
}  # fmt: skip
#: The joint every set is made relative to (root translation removed).
ROOT_JOINT = "pelvis"


def joint_set_positions(pos: np.ndarray, joint_names: Sequence[str], joint_set: Sequence[str]) -> np.ndarray | None:
    """Positions ``(T, K, 3)`` of ``joint_set`` relative to the pelvis, or None if a joint is missing.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, 3)], metres
    joint_names : sequence of str, length J
    joint_set : sequence of str, length K
    """
    names = list(joint_names)
    if ROOT_JOINT not in names or any(j not in names for j in joint_set):
        return None
    pos = np.asarray(pos, dtype=np.float64)
    rel = pos - pos[:, names.index(ROOT_JOINT)][:, None, :]
    picked: np.ndarray = rel[:, [names.index(j) for j in joint_set]]
    return picked


def paper_statistics(
    pred_pos: np.ndarray, fps: float, joint_names: Sequence[str], gt_pos: np.ndarray | None = None
) -> dict:
    """Acceleration and jerk on each paper's joint set (:data:`PAPER_JOINT_SETS`), root translation removed.

    Returns
    -------
    dict
        Per set present in the skeleton: ``joints``, ``pred`` (as :func:`motion_statistics`) and, with
        ``gt_pos``, ``gt`` and ``ratio_to_gt``.
    """
    out: dict = {}
    for name, joints in PAPER_JOINT_SETS.items():
        p = joint_set_positions(pred_pos, joint_names, joints)
        if p is None:
            continue
        entry: dict = {"joints": list(joints), "pred": motion_statistics(p, fps, joints)}
        g = None if gt_pos is None else joint_set_positions(gt_pos, joint_names, joints)
        if g is not None:
            entry["gt"] = motion_statistics(g, fps, joints)
            entry["ratio_to_gt"] = statistics_ratio(entry["pred"], entry["gt"])
        out[name] = entry
    return out


def statistics_ratio(pred_stats: dict, gt_stats: dict) -> dict:
    """Ratios pred/gt of the overall acceleration and jerk (1.0 = as lively/smooth as the ground truth).

    A ratio, not a difference, because Gesticulator §6.3 found perceived naturalness tracks how close jerk is
    to the ground truth's in relative terms (half vs double).
    """
    out = {}
    for key in ("acceleration_cm_s2", "jerk_cm_s3"):
        g = gt_stats[key]
        out[key.split("_")[0] + "_ratio"] = float(pred_stats[key] / g) if g > 0 else float("nan")
    return out


def speed_histogram(speed_cm_s: np.ndarray, bin_cm_s: float = 1.0, max_cm_s: float | None = None) -> tuple:
    """Relative-frequency histogram of speeds in fixed-width bins (Gesticulator §6.1.2 uses 1 cm/s).

    Parameters
    ----------
    speed_cm_s : ndarray, cm/s
        Any shape; flattened.
    bin_cm_s : float
        Bin width, cm/s.
    max_cm_s : float, optional
        Upper edge; default the largest speed. Pass the same value for two histograms you compare.

    Returns
    -------
    hist : ndarray [shape=(B,)]
        Relative frequencies summing to 1 (all zeros if there are no samples).
    edges : ndarray [shape=(B + 1,)], cm/s
    """
    s = np.asarray(speed_cm_s, dtype=np.float64).ravel()
    top = float(s.max()) if max_cm_s is None and s.size else float(max_cm_s or 0.0)
    n_bins = max(1, int(np.ceil(top / bin_cm_s + 1e-12)))
    if n_bins * bin_cm_s <= top:
        n_bins += 1  # the maximum itself must fall inside the last bin
    edges = np.arange(n_bins + 1) * bin_cm_s
    hist, _ = np.histogram(s, bins=edges)
    total = hist.sum()
    return (hist / total if total else hist.astype(np.float64)), edges


def hellinger_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Hellinger distance ``sqrt(1 - Σ sqrt(p q))`` between two histograms on the same bins.

    Bounded in [0, 1] (0 identical, 1 disjoint support), so it stays meaningful where KL divergence blows up
    on empty bins. Inputs are normalised to sum 1; pad the shorter with zeros if lengths differ.
    """
    p = np.asarray(p, dtype=np.float64).ravel()
    q = np.asarray(q, dtype=np.float64).ravel()
    n = max(p.size, q.size)
    p = np.pad(p, (0, n - p.size))
    q = np.pad(q, (0, n - q.size))
    if (p < 0).any() or (q < 0).any() or p.sum() <= 0 or q.sum() <= 0:
        raise InputError("histograms must be non-negative with positive mass")
    bc = float(np.sum(np.sqrt(p / p.sum() * q / q.sum())))
    return float(np.sqrt(max(0.0, 1.0 - bc)))


def wrist_speed_comparison(
    pred_pos: np.ndarray, gt_pos: np.ndarray, fps: float, wrists: Sequence[int], bin_cm_s: float = 1.0
) -> dict:
    """Wrist speed histograms of pred and ground truth on shared 1 cm/s bins and their Hellinger distance.

    Parameters
    ----------
    pred_pos, gt_pos : ndarray [shape=(T, J, 3)], metres
        May differ in length (histograms are relative frequencies).
    fps : float
    wrists : sequence of int
        Joint indices pooled into one histogram (both wrists, as Gesticulator Fig. 4).

    Returns
    -------
    dict
        ``hellinger``, ``pred_hist``, ``gt_hist``, ``edges_cm_s``, ``pred_mean_cm_s``, ``gt_mean_cm_s``.
    """
    idx = list(wrists)
    sp = joint_speed(pred_pos, fps)[:, idx] * M_TO_CM
    sg = joint_speed(gt_pos, fps)[:, idx] * M_TO_CM
    top = float(max(sp.max(), sg.max()))
    hp, edges = speed_histogram(sp, bin_cm_s, top)
    hg, _ = speed_histogram(sg, bin_cm_s, top)
    return {
        "hellinger": hellinger_distance(hp, hg),
        "pred_hist": hp,
        "gt_hist": hg,
        "edges_cm_s": edges,
        "pred_mean_cm_s": float(sp.mean()),
        "gt_mean_cm_s": float(sg.mean()),
    }


def truncate_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Cut both arrays to the shorter length; returns them and how many frames were dropped in total."""
    n = min(len(pred), len(gt))
    return pred[:n], gt[:n], (len(pred) - n) + (len(gt) - n)


def maje_mad(pred_pos: np.ndarray, gt_pos: np.ndarray, fps: float) -> dict:
    """MAJE and MAD as the S2AG reference code computes them (used by Rhythmic Gesticulator §7.3.2).

    MAJE: mean absolute difference of the joint coordinates (over frames, joints and x/y/z, not a per-joint
    Euclidean distance, which is about twice as large). MAD: mean absolute difference of the coordinates' second
    differences, per frame² (no fps² factor), so the numbers compare with the papers' at the same frame rate.
    Both need frame-aligned motions, so the longer one is truncated to the shorter; ``dropped_frames`` says by how
    much.

    Parameters
    ----------
    pred_pos, gt_pos : ndarray [shape=(T, J, 3)], metres
    fps : float
        Frame rate of both (MAD depends on it: compare only at equal rates).

    Returns
    -------
    dict
        ``maje_mm``, ``mad_mm_per_frame2``, ``fps``, ``n_frames`` (used), ``dropped_frames``.
    """
    pred_pos = _check_pos(pred_pos, fps, 3, "pred")
    gt_pos = _check_pos(gt_pos, fps, 3, "gt")
    if pred_pos.shape[1:] != gt_pos.shape[1:]:
        raise InputError(f"pred and gt skeletons differ: {pred_pos.shape[1:]} vs {gt_pos.shape[1:]}")
    p, g, dropped = truncate_pair(pred_pos, gt_pos)
    maje = np.abs(p - g).mean() * M_TO_MM
    mad = np.abs(np.diff(p, n=2, axis=0) - np.diff(g, n=2, axis=0)).mean() * M_TO_MM
    return {
        "maje_mm": float(maje), "mad_mm_per_frame2": float(mad), "fps": float(fps), "n_frames": len(p),
        "dropped_frames": dropped,
    }  # fmt: skip


#: S2AG's evaluation windows (its ``config/multimodal_context_v2.yml``): 34 poses at 15 fps, the first 4 the seed.
S2AG_FPS, S2AG_WINDOW, S2AG_SEED_FRAMES = 15.0, 34, 4
#: TED Gesture's anchor: its poses are joint positions relative to the spine, which is fixed at the origin.
S2AG_ANCHOR = "spine"


def maje_mad_s2ag_protocol(
    pred_pos: np.ndarray, gt_pos: np.ndarray, fps: float, joint_names: Sequence[str]
) -> dict | None:
    """MAJE and MAD exactly as S2AG's evaluation code computes them, for comparison with its tables.

    The authors' ``push_samples`` works per 34-pose window at 15 fps on the 10 TED joints (positions relative to
    the spine): MAJE leaves out each window's 4 seed poses (given, not generated), MAD takes the second
    differences inside each window over all its poses. Here both motions are resampled to 15 fps (linear), cut
    into consecutive windows (a partial last window is dropped) and scored the same way; :func:`maje_mad` keeps
    the whole-take figure on all joints beside it.

    Parameters
    ----------
    pred_pos, gt_pos : ndarray [shape=(T, J, 3)], metres
    fps : float
    joint_names : sequence of str, length J

    Returns
    -------
    dict or None
        ``maje_mm``, ``mad_mm_per_frame2`` (at 15 fps), ``joints``, ``n_windows``; None when the skeleton lacks a
        TED joint or the motions are shorter than one window.
    """
    joints = PAPER_JOINT_SETS["s2ag"]
    names = list(joint_names)
    if any(j not in names for j in joints):
        return None
    p, g, _ = truncate_pair(_check_pos(pred_pos, fps, 3, "pred"), _check_pos(gt_pos, fps, 3, "gt"))
    t_src = np.arange(len(p)) / fps
    t = np.arange(0.0, t_src[-1] + 1e-9, 1.0 / S2AG_FPS) if len(p) else np.zeros(0)
    n_win = len(t) // S2AG_WINDOW
    if n_win == 0:
        return None
    idx = [names.index(j) for j in joints]
    anchor = names.index(S2AG_ANCHOR)

    def windows(pos: np.ndarray) -> np.ndarray:  # (W, 34, K, 3), relative to the spine, at 15 fps
        rel = (pos[:, idx] - pos[:, anchor][:, None]).reshape(len(pos), -1)  # (T, K*3)
        at = np.stack([np.interp(t, t_src, rel[:, c]) for c in range(rel.shape[1])], axis=1)
        return at[: n_win * S2AG_WINDOW].reshape(n_win, S2AG_WINDOW, len(idx), 3)

    wp, wg = windows(p), windows(g)
    maje = np.abs(wp[:, S2AG_SEED_FRAMES:] - wg[:, S2AG_SEED_FRAMES:]).mean() * M_TO_MM
    mad = np.abs(np.diff(wp, n=2, axis=1) - np.diff(wg, n=2, axis=1)).mean() * M_TO_MM
    return {"maje_mm": float(maje), "mad_mm_per_frame2": float(mad), "fps": S2AG_FPS, "joints": list(joints),
            "n_windows": int(n_win)}  # fmt: skip


def spans_to_mask(spans: Sequence[tuple[float, float]], n_frames: int, fps: float) -> np.ndarray:
    """Boolean frame mask ``(T,)``: frame ``t`` (at ``t / fps`` s) lies inside some ``[start, end)`` span."""
    t = np.arange(n_frames) / fps
    mask = np.zeros(n_frames, dtype=bool)
    for a, b in spans:
        mask |= (t >= a) & (t < b)
    return mask


def silence_behaviour(
    pos: np.ndarray, fps: float, silent: np.ndarray | Sequence[tuple[float, float]], wrists: Sequence[int]
) -> dict:
    """Mean wrist speed inside silent periods vs during speech.

    A speaking robot should settle when the speaker pauses; a ratio near 1 means it keeps gesturing through
    silences.

    Parameters
    ----------
    pos : ndarray [shape=(T, J, 3)], metres
    fps : float
    silent : ndarray [shape=(T,)] of bool, or sequence of (start_s, end_s)
        Silent frames, or silent spans in seconds.
    wrists : sequence of int
        Joint indices averaged.

    Returns
    -------
    dict
        ``silent_speed_cm_s``, ``speech_speed_cm_s`` (NaN where there are no such frames), ``ratio``
        (silent / speech), ``silent_fraction``.
    """
    pos = _check_pos(pos, fps, 2)
    n = pos.shape[0]
    if isinstance(silent, np.ndarray) and silent.dtype == bool:
        mask = silent
        if mask.shape != (n,):
            m = np.zeros(n, dtype=bool)
            k = min(n, mask.shape[0])
            m[:k] = mask[:k]  # mask at another length: align from the start, pad as speech
            mask = m
    else:
        mask = spans_to_mask(list(silent), n, fps)
    sp = joint_speed(pos, fps)[:, list(wrists)].mean(axis=1) * M_TO_CM  # (T-1,) speed between t and t+1
    seg_silent = mask[:-1] & mask[1:]  # a velocity sample counts as silent if both its frames are
    seg_speech = ~mask[:-1] & ~mask[1:]
    s_sil = float(sp[seg_silent].mean()) if seg_silent.any() else float("nan")
    s_sp = float(sp[seg_speech].mean()) if seg_speech.any() else float("nan")
    ratio = s_sil / s_sp if seg_silent.any() and seg_speech.any() and s_sp > 0 else float("nan")
    return {
        "silent_speed_cm_s": s_sil,
        "speech_speed_cm_s": s_sp,
        "ratio": float(ratio),
        "silent_fraction": float(mask.mean()),
    }
