"""Evaluate one prediction (human motion or robot trajectory) against optional ground truth and speech.

The result is a nested dict of plain numbers and arrays; :func:`robogest.fileio.to_jsonable` makes it JSON-safe and
:func:`summary_rows` picks the headline numbers for a table.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.eval.beats import beat_sync_report, stroke_sync
from robogest.eval.features import feature_distances, lexeme_entropy
from robogest.eval.kinematics import (
    maje_mad,
    maje_mad_s2ag_protocol,
    motion_statistics,
    paper_statistics,
    silence_behaviour,
    statistics_ratio,
    wrist_speed_comparison,
)
from robogest.eval.robot import joint_jerk, limit_violations, mask_runs, time_to_rest, tracking_error
from robogest.fileio import atomic_path, to_jsonable

if TYPE_CHECKING:
    from robogest.trajectory.types import Trajectory

#: Joints pooled for wrist histograms, wrist peaks and silence behaviour.
WRIST_NAMES = ("l_wrist", "r_wrist")


def wrist_indices(joint_names: Sequence[str]) -> list[int] | None:
    """Indices of the wrists in ``joint_names``, or None if the skeleton has none."""
    idx = [list(joint_names).index(n) for n in WRIST_NAMES if n in joint_names]
    return idx or None


def real_vs_real(gt_pos: np.ndarray, fps: float) -> dict:
    """The Fréchet distances of the real motion's first half against its second half: the noise floor below
    which FD_k / FD_g of a generated motion against the same real motion mean nothing (on one BEAT2 take
    FD_g real-vs-real is of the order of generated-vs-real, so FD_g is dominated by sampling noise; use FGD with
    a trained evaluator for comparisons with the papers)."""
    half = gt_pos.shape[0] // 2
    return feature_distances(gt_pos[:half], gt_pos[half:], fps)


def evaluate_motion(
    pred_pos: np.ndarray,
    fps: float,
    joint_names: Sequence[str],
    gt_pos: np.ndarray | None = None,
    audio_beats_s: np.ndarray | None = None,
    silent_spans: Sequence[tuple[float, float]] | None = None,
    n_shifts: int = 100,
    onsets_s: np.ndarray | None = None,
) -> dict:
    """All metrics of a generated human motion.

    Parameters
    ----------
    pred_pos : ndarray [shape=(T, J, 3)], metres
    fps : float
        Frame rate of both motions (resample the ground truth first).
    joint_names : sequence of str, length J
    gt_pos : ndarray [shape=(T', J, 3)], metres, optional
    audio_beats_s : ndarray [shape=(B,)], seconds, optional
        Onset beats (no pseudo-beats) for PMB and BeatAlign.
    silent_spans : sequence of (start_s, end_s), optional
    n_shifts : int
        Circular shifts for the chance-corrected beat scores.
    onsets_s : ndarray [shape=(K,)], seconds, optional
        :func:`robogest.eval.beats.stroke_sync_events` of the speech, for ``beat_sync.stroke_sync``.

    Returns
    -------
    dict
        ``pred`` (acceleration/jerk over all joints, root moving), ``paper_joint_sets`` (the same on each
        paper's joint set, root fixed: :data:`robogest.eval.kinematics.PAPER_JOINT_SETS`), and where the inputs
        allow: ``gt``, ``ratio_to_gt``, ``wrist_speed``, ``maje_mad`` (all joints, whole take), ``maje_mad_s2ag``
        (S2AG's protocol: TED joints, 15 fps windows, seed poses excluded), ``features`` (+ ``features_noise_floor``),
        ``beat_sync`` (+ ``gt_beat_sync``), ``silence``.
    """
    wr = wrist_indices(joint_names)
    out: dict = {"kind": "motion", "fps": float(fps), "n_frames": int(pred_pos.shape[0])}
    out["pred"] = motion_statistics(pred_pos, fps, joint_names)
    out["paper_joint_sets"] = paper_statistics(pred_pos, fps, joint_names, gt_pos)
    if gt_pos is not None:
        out["gt"] = motion_statistics(gt_pos, fps, joint_names)
        out["ratio_to_gt"] = statistics_ratio(out["pred"], out["gt"])
        if wr:
            out["wrist_speed"] = wrist_speed_comparison(pred_pos, gt_pos, fps, wr)
        out["maje_mad"] = maje_mad(pred_pos, gt_pos, fps)
        s2ag = maje_mad_s2ag_protocol(pred_pos, gt_pos, fps, joint_names)
        if s2ag is not None:
            out["maje_mad_s2ag"] = s2ag
        out["features"] = feature_distances(pred_pos, gt_pos, fps)
        out["features_noise_floor"] = real_vs_real(gt_pos, fps)
    if audio_beats_s is not None:
        spans = list(silent_spans or ())
        sync = functools.partial(beat_sync_report, wrists=wr, n_shifts=n_shifts, onsets_s=onsets_s, silent_spans=spans)
        out["beat_sync"] = sync(pred_pos, fps, audio_beats_s)
        if gt_pos is not None:
            out["gt_beat_sync"] = sync(gt_pos, fps, audio_beats_s)
    if silent_spans is not None and wr:
        out["silence"] = silence_behaviour(pred_pos, fps, list(silent_spans), wr)
    return out


def evaluate_trajectory(
    traj: Trajectory,
    gt_q_rad: np.ndarray | None = None,
    audio_beats_s: np.ndarray | None = None,
    silent_spans: Sequence[tuple[float, float]] | None = None,
    achieved_q_rad: np.ndarray | None = None,
    n_shifts: int = 100,
    onsets_s: np.ndarray | None = None,
    wrist_pos_m: np.ndarray | None = None,
) -> dict:
    """All metrics of a robot command trajectory.

    Parameters
    ----------
    traj : robogest.trajectory.types.Trajectory
    gt_q_rad : ndarray [shape=(T', J)], radians, optional
        Reference trajectory sampled at ``traj.t_s``; compared like a tracking error.
    audio_beats_s : ndarray, seconds, optional
        Beat sync is computed on joint-angle speed.
    silent_spans : sequence of (start_s, end_s), optional
        Default: the trajectory's own ``silent`` mask.
    achieved_q_rad : ndarray [shape=(T', J)], radians, optional
        Simulated or measured angles for the sim tracking error.
    onsets_s : ndarray [shape=(K,)], seconds, optional
    wrist_pos_m : ndarray [shape=(T, W, 3)], metres, optional
        The robot's wrist sites along the trajectory; with ``onsets_s`` and ``audio_beats_s`` gives
        ``beat_sync.stroke_sync`` on the robot itself.

    Returns
    -------
    dict
        ``limits``, ``jerk``, ``time_to_rest``; where the inputs allow ``joint_error``, ``jerk_ratio_to_gt``,
        ``tracking``, ``beat_sync``; ``lexeme_entropy`` (Rhythmic Gesticulator eq. 23) when the trajectory carries
        its generator's ``lexemes`` annotation.
    """
    fps = traj.fps
    q = traj.q_rad
    names = list(traj.joint_names)
    out: dict = {"kind": "trajectory", "fps": float(fps), "n_frames": int(traj.n_frames), "robot": traj.robot}
    out["limits"] = limit_violations(q, fps, traj.q_min_rad, traj.q_max_rad, traj.v_max_rad_s, traj.a_max_rad_s2, names)
    out["jerk"] = joint_jerk(q, fps, names)
    silent = traj.silent.astype(bool) if silent_spans is None else list(silent_spans)
    out["time_to_rest"] = time_to_rest(q, fps, silent, traj.rest_q_rad)
    notes = getattr(traj, "annotations", {})
    if "lexemes" in notes:
        n_lex = notes.get("n_lexemes")
        n_lex = int(np.asarray(n_lex).reshape(-1)[0]) if n_lex is not None else None
        out["lexeme_entropy"] = lexeme_entropy(np.asarray(notes["lexemes"]).astype(np.int64), n_lex)
        out["lexeme_entropy"].update(n_blocks=int(np.asarray(notes["lexemes"]).size), n_lexemes=n_lex)
    if gt_q_rad is not None:
        out["joint_error"] = tracking_error(q, gt_q_rad, names)
        gj = joint_jerk(gt_q_rad, fps, names)["mean_rad_s3"]
        out["jerk_ratio_to_gt"] = out["jerk"]["mean_rad_s3"] / gj if gj > 0 else float("nan")
    if achieved_q_rad is not None:
        out["tracking"] = tracking_error(q, achieved_q_rad, names)
    if audio_beats_s is not None and traj.n_frames >= 3:
        out["beat_sync"] = beat_sync_report(q[:, :, None], fps, audio_beats_s, None, n_shifts)
        if wrist_pos_m is not None and onsets_s is not None:
            spans = silent_spans
            if spans is None:
                spans = [(a / fps, b / fps) for a, b in mask_runs(traj.silent.astype(bool))]
            out["beat_sync"]["stroke_sync"] = stroke_sync(wrist_pos_m, fps, onsets_s, spans, n_shifts)
    return out


def _fmt(x: float, nd: int = 2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def _sync(d: dict) -> str:
    return f"{_fmt(d['score'])} (chance {_fmt(d['null_mean'])}±{_fmt(d['null_std'])}, z={_fmt(d['z'], 1)})"


def _stroke(d: dict) -> str:
    s = f"{_fmt(d['hit'])} (chance {_fmt(d['chance'])}±{_fmt(d['chance_std'])}, z={_fmt(d['z'], 1)})"
    return s + (f" vs {d['events']}" if d.get("events") else "")


def summary_rows(result: dict) -> list[tuple[str, str]]:
    """Headline ``(metric, value)`` rows of one result, in a fixed order, for the printed table."""
    if result["kind"] == "motion":
        return _motion_rows(result) + _reference_rows(result) + _beat_rows(result)
    return _trajectory_rows(result) + _beat_rows(result)


def _motion_rows(result: dict) -> list[tuple[str, str]]:
    """Smoothness of a human motion (on the Gesticulator paper's joints when the result has them: the paper
    these statistics come from) and its ratio to the ground truth."""
    sets = result.get("paper_joint_sets", {})
    p, r, where = result["pred"], result.get("ratio_to_gt"), "all joints"
    if "gesticulator" in sets:
        g = sets["gesticulator"]
        p, r, where = g["pred"], g.get("ratio_to_gt"), "Gesticulator joints"
    rows = [
        (f"acceleration (cm/s², {where})", _fmt(p["acceleration_cm_s2"])),
        (f"jerk (cm/s³, {where})", _fmt(p["jerk_cm_s3"])),
    ]
    if r is not None:
        rows += [("acceleration / gt", _fmt(r["acceleration_ratio"])), ("jerk / gt", _fmt(r["jerk_ratio"]))]
    if "wrist_speed" in result:
        rows.append(("wrist speed Hellinger", _fmt(result["wrist_speed"]["hellinger"], 3)))
    return rows


def _reference_rows(result: dict) -> list[tuple[str, str]]:
    """A human motion against its ground truth (joint errors, feature distances, FGD) and its silences."""
    rows: list[tuple[str, str]] = []
    if "maje_mad" in result:
        m = result["maje_mad"]
        note = f" ({m['dropped_frames']} frames truncated)" if m["dropped_frames"] else ""
        mad = (f"MAD (mm/frame² at {m['fps']:g} fps)", _fmt(m["mad_mm_per_frame2"]))
        rows += [("MAJE (mm)", _fmt(m["maje_mm"]) + note), mad]
    if "maje_mad_s2ag" in result:
        m = result["maje_mad_s2ag"]
        rows += [
            (f"MAJE, S2AG protocol (mm, {m['n_windows']} windows)", _fmt(m["maje_mm"])),
            ("MAD, S2AG protocol (mm/frame² at 15 fps)", _fmt(m["mad_mm_per_frame2"])),
        ]
    if "features" in result:
        f = result["features"]
        floor = result.get("features_noise_floor", {})
        rows += [
            ("FD kinetic (real vs real)", f"{_fmt(f['fd_kinetic'])} ({_fmt(floor.get('fd_kinetic', math.nan))})"),
            ("FD geometric (real vs real)", f"{_fmt(f['fd_geometric'])} ({_fmt(floor.get('fd_geometric', math.nan))})"),
            ("diversity kinetic (gt)", f"{_fmt(f['diversity_kinetic'])} ({_fmt(f['gt_diversity_kinetic'])})"),
        ]
    if "fgd" in result:
        f = result["fgd"]
        rows.append(("FGD, BEAT2 evaluator (real vs real)", f"{_fmt(f['fgd'], 4)} ({_fmt(f['real_vs_real'], 4)})"))
    if "silence" in result:
        s = result["silence"]
        speeds = f"{_fmt(s['silent_speed_cm_s'])} / {_fmt(s['speech_speed_cm_s'])}"
        rows.append(("wrist speed silent / speech (cm/s)", speeds))
    return rows


def _trajectory_rows(result: dict) -> list[tuple[str, str]]:
    """A robot trajectory: limit violations, jerk, time to rest, errors against a reference and the measured
    motion, and its generator's lexeme entropy."""
    lim = result["limits"]
    rows = [
        (f"{k} limit violations (max excess)", f"{lim[k]['count']} ({_fmt(lim[k]['max_excess'], 4)})")
        for k in ("position", "velocity", "acceleration")
    ]
    jerk = result["jerk"]
    rows.append(("jerk mean / max (rad/s³)", f"{_fmt(jerk['mean_rad_s3'])} / {_fmt(jerk['max_rad_s3'])}"))
    t = result["time_to_rest"]
    rest = f"{_fmt(t['mean_s'])} / {_fmt(t['max_s'])}, {t['n_unreached']}/{t['n_spans']} unreached"
    rows.append(("time to rest mean / max (s)", rest))
    if "joint_error" in result:
        rows.append(("joint error vs gt RMS (rad)", _fmt(result["joint_error"]["rms_rad"], 4)))
    if "tracking" in result:
        rows.append(("tracking error RMS (rad)", _fmt(result["tracking"]["rms_rad"], 4)))
    if "lexeme_entropy" in result:
        e = result["lexeme_entropy"]
        value = f"{_fmt(e['entropy_nats'])} ({_fmt(e['normalized'])} of log N_s, {e['n_blocks']} blocks)"
        rows.append(("lexeme entropy (nats)", value))
    return rows


def _beat_rows(result: dict) -> list[tuple[str, str]]:
    """Beat synchrony of the prediction and, for a motion with ground truth, of the ground truth (the bar)."""
    rows: list[tuple[str, str]] = []
    if "beat_sync" in result:
        b = result["beat_sync"]
        rows.append((f"PMB δ={b['pmb']['delta_s']}s (%)", _sync(b["pmb"])))
        rows.append((f"BeatAlign σ={b['beat_align']['sigma_s']}s", _sync(b["beat_align"])))
        if "stroke_sync" in b:
            lo, hi = b["stroke_sync"]["window_s"]
            rows.append((f"stroke sync {lo:g}..{hi:g}s (hit rate)", _stroke(b["stroke_sync"])))
    if "gt_beat_sync" in result:
        rows.append(("gt PMB δ=0.2s (%)", _sync(result["gt_beat_sync"]["pmb"])))
        if "stroke_sync" in result["gt_beat_sync"]:
            rows.append(("gt stroke sync (hit rate)", _stroke(result["gt_beat_sync"]["stroke_sync"])))
    return rows


def write_json_atomic(data: dict, path: str | Path) -> None:
    """Write JSON so that a crash never leaves a half-written file."""
    path = Path(path)
    text = json.dumps(to_jsonable(data), indent=2, allow_nan=False)
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as e:
        raise InputError(f"{path}: cannot write JSON ({e})") from None
