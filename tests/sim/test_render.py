"""Video and PNG rendering (small sizes, a few frames: software GL is slow)."""

from __future__ import annotations

import av
import numpy as np
import pytest

from robogest.backends.mujoco_sim import simulate, sine_test_trajectory
from robogest.backends.render import VideoWriter, render_png
from robogest.errors import InputError, MissingDependencyError
from robogest.robot.registry import find_robot


@pytest.fixture(scope="module")
def robot():
    return find_robot("humanoid_xl430")


def _needs_renderer(fn, *a, **kw):
    try:
        return fn(*a, **kw)
    except MissingDependencyError as e:  # no GL on this machine: the error itself is what we promise
        assert "install" in str(e)
        pytest.skip(f"no offscreen GL here: {e}")


def test_video_with_audio(tmp_path, robot):
    traj = sine_test_trajectory(robot, duration_s=0.36, fps=50)
    sr = 16000
    audio = (0.2 * np.sin(2 * np.pi * 200 * np.arange(int(0.4 * sr)) / sr)).astype(np.float32)
    out = tmp_path / "clip.mp4"
    rep = _needs_renderer(simulate, traj, robot, video_path=out, audio=audio, audio_sr=sr, width=160, height=120)
    assert rep.video_path == out and out.is_file()
    # 0.4 s of audio at 25 fps, frame 0 included (11 frames), then the glide to rest and settling (< 0.5 s)
    assert 11 <= rep.n_video_frames <= 11 + 13
    assert rep.render_s_per_frame > 0
    assert [p.name for p in tmp_path.iterdir()] == ["clip.mp4"], "no temp file left behind"
    with av.open(str(out)) as c:
        kinds = {s.type: s for s in c.streams}
        assert kinds["video"].codec_context.name == "h264"
        assert (kinds["video"].codec_context.width, kinds["video"].codec_context.height) == (160, 120)
        assert kinds["audio"].codec_context.name == "aac"
        assert kinds["audio"].codec_context.sample_rate == sr
        frames = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    assert len(frames) == rep.n_video_frames
    assert frames[0].std() > 10, "the image shows something, not a blank frame"


def test_writer_abort_leaves_nothing(tmp_path):
    out = tmp_path / "x.mp4"
    with pytest.raises(RuntimeError), VideoWriter(out, 32, 32, audio=np.zeros(100), audio_sr=22050) as w:
        w.add_frame(np.zeros((32, 32, 3), np.uint8))
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_odd_size_rejected(tmp_path, robot):
    with pytest.raises(InputError, match="even"):
        simulate(sine_test_trajectory(robot, duration_s=0.1), robot, video_path=tmp_path / "a.mp4", width=161)


def test_render_png_rest_and_pose(tmp_path, robot):
    from matplotlib import image as mpimg

    a = _needs_renderer(render_png, robot, None, tmp_path / "rest.png", width=160, height=120)
    q = robot.rest_q_rad.copy()
    q[robot.joint_names.index("r_shoulder_roll")] = 1.5  # right arm out sideways: appears on the image's left
    b = render_png(robot, q, tmp_path / "pose.png", width=160, height=120)
    ia, ib = mpimg.imread(a), mpimg.imread(b)
    assert ia.shape[:2] == (120, 160)
    diff = np.abs(ia[..., :3] - ib[..., :3]).sum(axis=2) > 0.1
    cols = np.nonzero(diff.any(axis=0))[0]
    assert cols.size and cols.mean() < 80, "the robot faces the camera: its right arm is on the image's left"
    with pytest.raises(InputError):
        render_png(robot, np.zeros(3), tmp_path / "bad.png")
