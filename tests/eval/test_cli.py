"""``robogest eval`` end to end on tiny self-made files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.trajectory.types import Trajectory

FPS = 50.0


def make_traj(path, freq_hz: float = 0.5, seconds: float = 6.0, spike: bool = False) -> None:
    t = np.arange(round(seconds * FPS)) / FPS
    q = np.stack([0.4 * np.sin(2 * np.pi * freq_hz * t), 0.2 * np.cos(2 * np.pi * freq_hz * t)], axis=1)
    silent = (t >= 4.0) & (t < 5.0)
    ramp = np.clip(np.maximum(t - 3.0, 0.0) - 2.0 * np.maximum(t - 4.5, 0.0), 0.0, 1.0)  # 0→1 on 3–4 s, back by 5 s
    envelope = 0.5 * (1 + np.cos(np.pi * ramp))  # smooth: 1, down to 0 (rest) through the silence, up again
    q *= envelope[:, None]
    if spike:
        q[30, 0] = 2.0
    Trajectory(
        t_s=t,
        q_rad=q,
        joint_names=["shoulder", "elbow"],
        q_min_rad=np.array([-1.5, -1.5]),
        q_max_rad=np.array([1.5, 1.5]),
        v_max_rad_s=np.array([5.0, 5.0]),
        a_max_rad_s2=np.array([50.0, 50.0]),
        rest_q_rad=np.zeros(2),
        silent=silent,
        robot="test",
    ).save(path)


def test_trajectory_pair_json_and_plots(tmp_path, capsys):
    make_traj(tmp_path / "pred" / "clip1.npz", spike=True)
    make_traj(tmp_path / "gt" / "clip1.npz", freq_hz=0.7)
    out = tmp_path / "out" / "m.json"
    rc = main(
        ["eval", "--pred", str(tmp_path / "pred"), "--gt", str(tmp_path / "gt"), "--json", str(out),
         "--plots", str(tmp_path / "plots")]
    )  # fmt: skip
    assert rc == 0
    data = json.loads(out.read_text())
    r = data["results"]["clip1"]
    assert r["kind"] == "trajectory"
    assert {"limits", "jerk", "time_to_rest", "joint_error", "jerk_ratio_to_gt", "files"} <= set(r)
    assert r["limits"]["position"]["count"] == 1
    assert r["time_to_rest"]["n_spans"] == 1 and r["time_to_rest"]["per_span"][0]["time_to_rest_s"] == 0.0
    assert (tmp_path / "plots" / "clip1_trajectory.png").stat().st_size > 1000
    assert "limit violations" in capsys.readouterr().out


def test_pred_alone_prints_what_needs_no_ground_truth(tmp_path, capsys):
    make_traj(tmp_path / "a.npz")
    assert main(["eval", "--pred", str(tmp_path / "a.npz"), "--json", str(tmp_path / "a.json")]) == 0
    r = json.loads((tmp_path / "a.json").read_text())["results"]["a"]
    assert r["limits"]["total"] == 0 and "joint_error" not in r


def test_bvh_motion_pair(tmp_path):
    motion = pytest.importorskip("robogest.motion")
    if not hasattr(motion, "save_bvh"):
        pytest.skip("robogest.motion.save_bvh not available yet")
    from robogest.motion import rotations as R

    def make(seconds: float, freq: float, fps: float):
        m = motion.HumanMotion.rest(round(seconds * fps), fps)
        t = m.t_s
        for name, sign in (("l_shoulder", 1), ("r_shoulder", -1), ("l_elbow", 1)):
            j = m.skeleton.index(name)
            ang = sign * 0.5 * np.sin(2 * np.pi * freq * t)
            m.rotations[:, j] = R.from_axis_angle(np.stack([np.zeros_like(t), np.zeros_like(t), ang], 1))
        return m

    (tmp_path / "p").mkdir()
    (tmp_path / "g").mkdir()
    motion.save_bvh(make(6.0, 1.0, 30.0), tmp_path / "p" / "s.bvh")
    motion.save_bvh(make(6.0, 0.8, 60.0), tmp_path / "g" / "s.bvh")  # other fps: resampled
    out = tmp_path / "m.json"
    argv = ["eval", "--pred", str(tmp_path / "p"), "--gt", str(tmp_path / "g"), "--json", str(out)]
    assert main([*argv, "--plots", str(tmp_path / "plots")]) == 0
    r = json.loads(out.read_text())["results"]["s"]
    assert {"pred", "gt", "ratio_to_gt", "wrist_speed", "maje_mad", "features"} <= set(r)
    assert r["gt_resampled_from_fps"] == 60.0 and r["fps"] == 30.0
    assert r["maje_mad"]["maje_mm"] > 0 and 0 < r["wrist_speed"]["hellinger"] < 1
    assert (tmp_path / "plots" / "s_wrist_speed.png").exists()


def test_bad_path_exit_2_one_line(tmp_path, capsys):
    missing = tmp_path / "nope.npz"
    assert main(["eval", "--pred", str(missing)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(missing) in err


def test_corrupt_file_exit_2_names_file(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    assert main(["eval", "--pred", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.npz" in err


def test_unpaired_stem_is_an_input_error(tmp_path, capsys):
    make_traj(tmp_path / "p" / "one.npz")
    make_traj(tmp_path / "g" / "two.npz")
    assert main(["eval", "--pred", str(tmp_path / "p"), "--gt", str(tmp_path / "g")]) == 2
    assert "one" in capsys.readouterr().err


def test_trajectory_with_audio_reports_chance_corrected_beats(tmp_path):
    pytest.importorskip("robogest.speech")
    from scipy.io import wavfile

    sr = 16000
    t = np.arange(int(6.0 * sr)) / sr
    bursts = np.zeros_like(t)
    for start in np.arange(0.2, 3.8, 0.33):  # syllable-like tone bursts, then a pause from 3.8 s
        bursts += (t >= start) & (t < start + 0.15)
    tail = (t >= 5.0) & (np.mod(t - 5.0, 0.33) < 0.15)
    audio = 0.5 * np.sin(2 * np.pi * 220 * t) * np.clip(bursts + tail, 0, 1)
    wavfile.write(tmp_path / "a.wav", sr, (audio * 32767).astype(np.int16))
    make_traj(tmp_path / "a.npz")
    out = tmp_path / "a.json"
    rc = main(["eval", "--pred", str(tmp_path / "a.npz"), "--audio", str(tmp_path / "a.wav"), "--json", str(out)])
    assert rc == 0
    b = json.loads(out.read_text())["results"]["a"]["beat_sync"]
    assert b["n_audio_beats"] > 5
    assert {"score", "null_mean", "null_std", "z", "n_shifts"} <= set(b["pmb"]) and b["pmb"]["n_shifts"] == 100


def test_trajectory_without_lexemes_has_no_lexeme_entropy_and_one_with_has_it(tmp_path):
    make_traj(tmp_path / "a.npz")
    traj = Trajectory.load(tmp_path / "a.npz")
    assert traj.annotations == {}
    assert main(["eval", "--pred", str(tmp_path / "a.npz"), "--json", str(tmp_path / "a.json")]) == 0
    assert "lexeme_entropy" not in json.loads((tmp_path / "a.json").read_text())["results"]["a"]
    traj.annotations = {"lexemes": np.array([0, 0, 1, 1]), "n_lexemes": np.int64(4)}
    traj.save(tmp_path / "b.npz")
    np.testing.assert_array_equal(Trajectory.load(tmp_path / "b.npz").annotations["lexemes"], [0, 0, 1, 1])
    assert main(["eval", "--pred", str(tmp_path / "b.npz"), "--json", str(tmp_path / "b.json")]) == 0
    ent = json.loads((tmp_path / "b.json").read_text())["results"]["b"]["lexeme_entropy"]
    assert ent["entropy_nats"] == pytest.approx(np.log(2)) and ent["normalized"] == pytest.approx(0.5)
