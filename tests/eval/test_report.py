"""The per-file report: every section present, table rows formatted, strict JSON out."""

from __future__ import annotations

import json

import numpy as np

from robogest.eval.report import evaluate_motion, summary_rows, to_jsonable, write_json_atomic

NAMES = ("pelvis", "l_wrist", "r_wrist")


def test_evaluate_motion_all_sections_and_strict_json(tmp_path, rng):
    fps = 30.0
    t = np.arange(300) / fps
    pos = np.zeros((t.size, 3, 3)) + rng.normal(size=(1, 3, 3))
    pos[:, 1:, 0] += 0.1 * np.sin(2 * np.pi * t)[:, None]
    gt = pos + 0.01 * rng.normal(size=pos.shape)
    r = evaluate_motion(pos, fps, NAMES, gt, np.arange(0.5, 10, 0.4), [(4.0, 5.0)], n_shifts=20)
    assert {"pred", "gt", "ratio_to_gt", "wrist_speed", "maje_mad", "features", "beat_sync", "gt_beat_sync",
            "silence"} <= set(r)  # fmt: skip
    names = [n for n, _ in summary_rows(r)]
    assert "MAJE (mm)" in names and any(n.startswith("PMB") for n in names)
    write_json_atomic(r, tmp_path / "r.json")
    back = json.loads((tmp_path / "r.json").read_text())  # would fail on NaN/ndarray
    assert back["beat_sync"]["pmb"]["n_shifts"] == 20


def test_to_jsonable_nan_to_null():
    assert to_jsonable({"a": np.array([1.0, np.nan]), "b": np.float32(2.5), "c": (float("inf"),)}) == {
        "a": [1.0, None],
        "b": 2.5,
        "c": [None],
    }


def test_fd_is_reported_beside_its_real_vs_real_noise_floor():
    """FD_k/FD_g come with the distance between the real motion's two halves, below which they mean nothing."""
    from robogest.eval.report import evaluate_motion, real_vs_real

    rng = np.random.default_rng(0)
    gt = np.cumsum(rng.normal(0, 0.002, (400, 3, 3)), axis=0)  # (T, J, 3) random walk, metres
    pred = np.cumsum(rng.normal(0, 0.004, (400, 3, 3)), axis=0)
    r = evaluate_motion(pred, 20.0, ["a", "b", "c"], gt)
    floor = real_vs_real(gt, 20.0)
    assert r["features_noise_floor"] == floor
    assert np.isfinite(floor["fd_geometric"]) and floor["fd_geometric"] > 0  # two halves of one take differ
