"""Closed-form checks of acceleration/jerk, histograms, MAJE/MAD and silence behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.eval.kinematics import (
    hellinger_distance,
    maje_mad,
    motion_statistics,
    silence_behaviour,
    speed_histogram,
    statistics_ratio,
    wrist_speed_comparison,
)

FPS = 60.0


def sine_motion(amp_m: float, freq_hz: float, seconds: float, fps: float = FPS, n_joints: int = 2) -> np.ndarray:
    """Every joint moves along x as ``amp sin(ω t)``; ``(T, J, 3)`` metres."""
    t = np.arange(round(seconds * fps) + 1) / fps
    pos = np.zeros((t.size, n_joints, 3))
    pos[:, :, 0] = amp_m * np.sin(2 * np.pi * freq_hz * t)[:, None]
    return pos


def test_sine_acceleration_and_jerk_match_closed_form():
    amp, f = 0.1, 1.0
    w = 2 * np.pi * f
    s = motion_statistics(sine_motion(amp, f, 5.0), FPS, ["a", "b"])
    # mean |A ω^k sin| over whole periods = A ω^k · 2/π; in cm
    assert s["acceleration_cm_s2"] == pytest.approx(100 * amp * w**2 * 2 / np.pi, rel=0.01)
    assert s["jerk_cm_s3"] == pytest.approx(100 * amp * w**3 * 2 / np.pi, rel=0.01)
    assert s["per_joint_jerk_cm_s3"]["b"] == pytest.approx(s["jerk_cm_s3"])


def test_ratio_to_ground_truth_scales_with_amplitude_and_frequency():
    gt = motion_statistics(sine_motion(0.1, 1.0, 5.0), FPS)
    pred = motion_statistics(sine_motion(0.05, 2.0, 5.0), FPS)  # acc ∝ A f², jerk ∝ A f³
    r = statistics_ratio(pred, gt)
    assert r["acceleration_ratio"] == pytest.approx(0.5 * 4, rel=0.02)
    assert r["jerk_ratio"] == pytest.approx(0.5 * 8, rel=0.03)


def test_hellinger_identical_zero_disjoint_one():
    p = np.array([0.2, 0.3, 0.5, 0.0])
    assert hellinger_distance(p, p) == pytest.approx(0.0, abs=1e-7)
    assert hellinger_distance([1, 1, 0, 0], [0, 0, 2, 5]) == pytest.approx(1.0)
    mid = hellinger_distance([1, 0], [1, 1])  # BC = sqrt(1/2)
    assert mid == pytest.approx(np.sqrt(1 - np.sqrt(0.5)))


def test_speed_histogram_uses_one_cm_per_s_bins():
    hist, edges = speed_histogram(np.array([0.5, 0.7, 2.2, 2.9]), 1.0)
    assert np.allclose(np.diff(edges), 1.0)
    assert hist.tolist() == [0.5, 0.0, 0.5]


def test_wrist_histograms_same_motion_zero_faster_motion_positive():
    a = sine_motion(0.1, 1.0, 5.0)
    same = wrist_speed_comparison(a, a.copy(), FPS, [0, 1])
    assert same["hellinger"] == pytest.approx(0.0, abs=1e-7)
    faster = wrist_speed_comparison(sine_motion(0.1, 3.0, 5.0), a, FPS, [0, 1])
    assert faster["hellinger"] > 0.3
    assert faster["pred_mean_cm_s"] == pytest.approx(3 * faster["gt_mean_cm_s"], rel=0.02)


def test_maje_mad_constant_offset_and_truncation():
    gt = sine_motion(0.1, 1.0, 2.0)
    pred = gt + np.array([0.03, 0.04, 0.0])  # 5 cm away everywhere, same acceleration
    r = maje_mad(pred[:-10], gt, FPS)
    assert r["maje_mm"] == pytest.approx((30.0 + 40.0 + 0.0) / 3)  # mean |difference| over x, y, z (reference)
    assert r["mad_mm_per_frame2"] == pytest.approx(0.0, abs=1e-6)
    assert r["dropped_frames"] == 10 and r["n_frames"] == gt.shape[0] - 10


def test_mad_is_per_frame_squared_on_coordinates():
    """A constant extra acceleration of a mm/frame² along x: second difference a on x, 0 on y and z, at any fps."""
    gt = sine_motion(0.1, 1.0, 2.0)
    t = np.arange(gt.shape[0], dtype=float)[:, None]
    pred = gt.copy()
    pred[..., 0] += 0.5 * 0.006 * t**2  # 6 mm/frame² on x
    for fps in (FPS, 2 * FPS):
        assert maje_mad(pred, gt, fps)["mad_mm_per_frame2"] == pytest.approx(6.0 / 3, rel=1e-6)


def test_s2ag_protocol_excludes_each_windows_seed_poses_and_uses_the_ted_joints():
    """S2AG's code scores 34-pose windows at 15 fps on the 10 TED joints relative to the spine, leaving the 4 seed
    poses of each window out of MAJE; an error only in seed poses, or only in a non-TED joint, scores zero."""
    from robogest.eval.kinematics import S2AG_SEED_FRAMES, S2AG_WINDOW, maje_mad_s2ag_protocol
    from robogest.motion.skeleton import CANONICAL

    n = 3 * S2AG_WINDOW  # three windows at 15 fps
    rng = np.random.default_rng(0)
    gt = rng.normal(0, 0.1, (n, CANONICAL.n_joints, 3))
    names = CANONICAL.names
    pred = gt.copy()
    seed = (np.arange(n) % S2AG_WINDOW) < S2AG_SEED_FRAMES
    pred[np.ix_(seed, [names.index("l_wrist")])] += 0.05  # wrong only where windows are seeded with the truth
    pred[:, names.index("l_collar")] += 0.2  # not a TED joint
    r = maje_mad_s2ag_protocol(pred, gt, 15.0, names)
    assert r["n_windows"] == 3 and len(r["joints"]) == 10
    assert r["maje_mm"] == pytest.approx(0.0, abs=1e-9)
    assert r["mad_mm_per_frame2"] > 0  # MAD keeps every pose of the window
    pred2 = gt.copy()
    pred2[:, names.index("r_wrist"), 0] += 0.03  # 30 mm on x of one TED joint out of 10 (x, y, z)
    assert maje_mad_s2ag_protocol(pred2, gt, 15.0, names)["maje_mm"] == pytest.approx(30.0 / 30)
    assert maje_mad_s2ag_protocol(gt[:20], gt[:20], 15.0, names) is None  # shorter than one window


def test_maje_rejects_different_skeletons():
    with pytest.raises(InputError):
        maje_mad(np.zeros((10, 3, 3)), np.zeros((10, 4, 3)), FPS)


def test_frozen_in_silence_scores_zero_silent_speed():
    pos = sine_motion(0.1, 1.0, 6.0)
    t = np.arange(pos.shape[0]) / FPS
    frozen = (t >= 2.0) & (t < 4.0)
    pos[frozen] = pos[np.flatnonzero(frozen)[0]]
    spans = [(2.0, 4.0)]
    r = silence_behaviour(pos, FPS, spans, [0, 1])
    assert r["silent_speed_cm_s"] == 0.0
    assert r["speech_speed_cm_s"] > 10.0
    assert r["ratio"] == 0.0
    mask_r = silence_behaviour(pos, FPS, frozen, [0, 1])
    assert mask_r["silent_speed_cm_s"] == 0.0 and mask_r["silent_fraction"] == pytest.approx(frozen.mean())


def test_moving_through_silence_is_reported():
    pos = sine_motion(0.1, 1.0, 6.0)
    r = silence_behaviour(pos, FPS, [(2.0, 4.0)], [0])
    assert r["ratio"] == pytest.approx(1.0, rel=0.1)


def test_nan_input_is_an_input_error():
    pos = sine_motion(0.1, 1.0, 1.0)
    pos[3, 0, 0] = np.nan
    with pytest.raises(InputError):
        motion_statistics(pos, FPS)


def test_paper_joint_sets_fix_the_root_and_keep_each_papers_joints():
    """A pelvis that only slides moves every joint in world space, but no joint of a paper's set (root fixed)."""
    from robogest.eval.kinematics import PAPER_JOINT_SETS, paper_statistics
    from robogest.motion.skeleton import CANONICAL

    names = list(CANONICAL.names)
    pos = np.tile(CANONICAL.offsets_m.cumsum(axis=0)[None], (121, 1, 1))  # any fixed pose
    slide = sine_motion(0.2, 1.0, 2.0, n_joints=1)  # (121, 1, 3)
    moved = pos + slide
    wrist = names.index("l_wrist")
    moved[:, wrist, 1] += 0.1 * np.sin(2 * np.pi * 2.0 * np.arange(121) / FPS)  # the wrist also waves
    assert motion_statistics(moved, FPS, names)["per_joint_acceleration_cm_s2"]["head"] > 100
    sets = paper_statistics(moved, FPS, names, gt_pos=moved)
    assert set(sets) == {"gesticulator", "s2ag"}
    g = sets["gesticulator"]
    assert len(g["joints"]) == 13 and "pelvis" not in g["joints"] and "nose" not in g["joints"]
    assert len(sets["s2ag"]["joints"]) == 10 == len(PAPER_JOINT_SETS["s2ag"])
    per = g["pred"]["per_joint_acceleration_cm_s2"]
    assert per["head"] == pytest.approx(0.0, abs=1e-6) and per["l_wrist"] > 100
    assert g["pred"]["acceleration_cm_s2"] == pytest.approx(per["l_wrist"] / 13, rel=1e-9)
    assert g["ratio_to_gt"]["jerk_ratio"] == pytest.approx(1.0)


def test_paper_joint_sets_are_skipped_on_skeletons_without_their_joints():
    from robogest.eval.kinematics import paper_statistics

    assert paper_statistics(sine_motion(0.1, 1.0, 1.0, n_joints=3), FPS, ("pelvis", "l_wrist", "r_wrist")) == {}
