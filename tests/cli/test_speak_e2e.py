"""End-to-end: the CLI as a user runs it, in-process (the same `main` the console script calls)."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.robot import find_robot
from robogest.safety import JointLimits, long_silent_spans, rest_reach_time_s
from robogest.trajectory import Trajectory

SENTENCE = "Hello! You and I are talking. ... Maybe this is a big idea."


def check_trajectory(traj: Trajectory, rest_after_s: float = 1.0) -> None:
    """Every limit holds and rest is held in every long silent period."""
    fps = traj.fps
    dt = 1.0 / fps
    tol = 1e-9
    q = traj.q_rad
    assert (q >= traj.q_min_rad - tol).all() and (q <= traj.q_max_rad + tol).all()
    v = np.diff(q, axis=0)
    assert (np.abs(v) <= traj.v_max_rad_s * dt + tol).all()
    assert (np.abs(np.diff(v, axis=0)) <= traj.a_max_rad_s2 * dt * dt + tol).all()
    np.testing.assert_allclose(q[-1], traj.rest_q_rad, atol=1e-9)
    lim = JointLimits.from_robot(find_robot(traj.robot))
    reach = rest_reach_time_s(None, lim, fps)
    for a, b in long_silent_spans(traj.silent, fps, rest_after_s):
        k0 = a + int(np.ceil(reach * fps))
        k1 = b - int(np.ceil(0.4 * fps))
        if k1 > k0:
            np.testing.assert_allclose(q[k0:k1], np.broadcast_to(traj.rest_q_rad, q[k0:k1].shape), atol=1e-9)


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("speak", "play", "analyze", "generate", "robots"):
        assert cmd in out
    assert "exit codes" in out


def test_speak_saves_safe_trajectory(tmp_path, capsys):
    out = tmp_path / "demo.npz"
    assert main(["speak", SENTENCE, "--save", str(out)]) == 0
    traj = Trajectory.load(out)
    assert traj.robot == "humanoid_xl430" and traj.q_rad.shape[1] == 11
    assert traj.silent.any()  # the "..." pause and the ends are silent
    check_trajectory(traj)
    assert (tmp_path / "demo.wav").is_file() and traj.audio_path.endswith("demo.wav")
    assert np.ptp(traj.q_rad, axis=0).max() > 0.2  # it really gestures
    text = capsys.readouterr().out
    assert "sim tracking error" in text


@pytest.mark.parametrize("robot", ["humanoid_xl430", "humanoid_sts3215", "desk_arm_sts3215", "so101_sts3215"])
def test_every_robot_speaks_within_limits(robot, tmp_path):
    out = tmp_path / f"{robot}.npz"
    assert main(["speak", SENTENCE, "--robot", robot, "--save", str(out)]) == 0
    traj = Trajectory.load(out)
    check_trajectory(traj)
    assert np.ptp(traj.q_rad, axis=0).max() > 0.2


def test_play_saved_trajectory_and_refuse_wrong_robot(tmp_path, capsys):
    out = tmp_path / "t.npz"
    assert main(["speak", "Hi there.", "--save", str(out)]) == 0
    assert main(["play", str(out)]) == 0
    capsys.readouterr()
    assert main(["play", str(out), "--robot", "desk_arm_sts3215"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pass the --robot it was made for (humanoid_xl430)" in err[0]


def test_play_refuses_trajectory_breaking_limits(tmp_path, capsys):
    out = tmp_path / "t.npz"
    assert main(["speak", "Hi there.", "--save", str(out)]) == 0
    traj = Trajectory.load(out)
    traj.q_rad[len(traj.q_rad) // 2, 0] += 0.5  # a jump no servo may make
    traj.save(out)
    assert main(["play", str(out)]) == 4
    assert "refusing to play" in capsys.readouterr().err


def test_generate_writes_bvh(tmp_path):
    from robogest.motion import load_bvh

    out = tmp_path / "m.bvh"
    assert (
        main(["generate", "--text", "Yes, I agree with you.", "--out", str(out), "--plot", str(tmp_path / "m.png")])
        == 0
    )
    m = load_bvh(out)
    assert m.n_frames > 10 and (tmp_path / "m.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("argv", "code", "pattern"),
    [
        (["speak"], 2, "give either text to speak"),
        (["speak", "hi", "--audio", "x.wav"], 2, "not both"),
        (["speak", "--audio", "/nonexistent/talk.wav"], 2, "/nonexistent/talk.wav"),
        (["speak", "hi", "--robot", "nope"], 3, "unknown robot 'nope'; known robots: .*humanoid_xl430"),
        (["speak", "hi", "--generator", "nope"], 2, "unknown generator 'nope'"),
        (["speak", "hi", "--checkpoint", "w.pt"], 2, "needs none"),
        (["play", "/nonexistent/m.bvh"], 2, "no such motion file"),
    ],
)
def test_user_errors_are_one_line(argv, code, pattern, capsys):
    import re

    assert main(argv) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("robogest: error: ") and re.search(pattern, err[0])


def test_video_has_audio_and_frames(tmp_path):
    av = pytest.importorskip("av")
    out = tmp_path / "v.mp4"
    try:
        rc = main(["speak", "Hi there, you!", "--video", str(out)])
    except Exception as e:  # renderer unavailable on this machine
        pytest.skip(f"no offscreen renderer: {e}")
    if rc == 6:
        pytest.skip("no offscreen renderer on this machine")
    assert rc == 0
    with av.open(str(out)) as f:
        kinds = {s.type for s in f.streams}
        assert kinds == {"video", "audio"}
        assert f.streams.video[0].frames > 10 or f.duration > 0


def test_generate_writes_smplx_for_npz_and_refuses_other_names(tmp_path, capsys):
    """``generate --out h.npz`` wrote BVH text into the .npz-named file (exit 0); now it is SMPL-X in BEAT2's
    layout, and a name that is neither .bvh nor .npz is refused before any work."""
    from robogest.motion import load_smplx

    out = tmp_path / "h.npz"
    assert main(["generate", "--text", "Hello there.", "--out", str(out)]) == 0
    assert np.load(out)["poses"].shape[1] == 165 and int(np.load(out)["mocap_frame_rate"]) == 30  # the FGD's rate
    assert load_smplx(out).n_frames > 10
    assert main(["generate", "--text", "Hello there.", "--out", str(tmp_path / "h.txt")]) == 2
    assert "h.txt: name the motion file .bvh (BVH) or .npz (SMPL-X parameters)" in capsys.readouterr().err
    assert not (tmp_path / "h.txt").exists()
