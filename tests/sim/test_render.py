"""Video and PNG rendering (small sizes, a few frames: software GL is slow)."""

from __future__ import annotations

import av
import numpy as np
import pytest

from robogest.backends import render
from robogest.backends.mujoco_sim import simulate, sine_test_trajectory
from robogest.backends.render import render_png
from robogest.errors import InputError, MissingDependencyError
from robogest.media.video import VideoWriter
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


# --- near real time: size and options by renderer, frames at the video's times, encoding on its own thread


@pytest.mark.parametrize(
    ("gl_name", "size", "cheap"),
    [("llvmpipe (LLVM 15.0.6, 256 bits)", (640, 360), True), ("NVIDIA H200/PCIe/SSE2", (1280, 720), False)],
)
def test_video_settings_by_renderer(monkeypatch, gl_name, size, cheap):
    monkeypatch.setattr(render, "gl_renderer_name", lambda: gl_name)
    auto = render.video_settings()
    assert ((auto.width, auto.height), auto.cheap, auto.renderer) == (size, cheap, gl_name)
    asked = render.video_settings(1280, 720)  # a size on request is kept; the options follow the renderer
    assert ((asked.width, asked.height), asked.cheap) == ((1280, 720), cheap)
    with pytest.raises(InputError, match="use even sizes"):
        render.video_settings(641, 360)


def _frame(model, data, robot, cheap: bool) -> tuple[np.ndarray, object]:
    r = _needs_renderer(render.make_renderer, model, 160, 90, cheap=cheap)
    try:
        r.update_scene(data, camera=render.video_camera(model, data, robot, 160, 90))
        flags = r.scene.flags.copy()
        return r.render().astype(float), flags
    finally:
        r.close()


def test_cheap_rendering_keeps_the_picture_and_the_model(robot):
    """The software renderer's options (no multisampling, a smaller shadow map, no reflections) change edges by a
    few levels, not what the frame shows; the shadow stays, and the model's own settings are left as they were."""
    import mujoco

    from robogest.backends.mujoco_sim import _reset_to, load_sim_model

    sim = load_sim_model(robot)
    data = mujoco.MjData(sim.model)
    _reset_to(sim, data, None)
    before = (int(sim.model.vis.quality.offsamples), int(sim.model.vis.quality.shadowsize))
    full, _ = _frame(sim.model, data, robot, cheap=False)
    cheap, flags = _frame(sim.model, data, robot, cheap=True)
    assert (int(sim.model.vis.quality.offsamples), int(sim.model.vis.quality.shadowsize)) == before
    assert flags[mujoco.mjtRndFlag.mjRND_SHADOW] and not flags[mujoco.mjtRndFlag.mjRND_REFLECTION]
    assert np.abs(cheap - full).mean() < 2.0, "the same picture, to within anti-aliased edges"


def test_frames_at_the_video_times_encoded_on_their_own_thread(tmp_path, robot, monkeypatch):
    import threading

    threads = set()
    add_frame = VideoWriter.add_frame

    def add_frame_on(self, rgb):
        threads.add(threading.current_thread().name)
        add_frame(self, rgb)

    monkeypatch.setattr(VideoWriter, "add_frame", add_frame_on)
    traj = sine_test_trajectory(robot, duration_s=0.5, fps=50)
    out = tmp_path / "t.mp4"
    rep = _needs_renderer(simulate, traj, robot, video_path=out, width=64, height=48, video_fps=20)
    stats = rep.extra["video"]
    t = np.array(stats.frame_times_s)
    assert len(t) == rep.n_video_frames >= 11  # 0.5 s at 20 fps, frame 0 included, then the glide to rest
    np.testing.assert_allclose(t, np.arange(len(t)) / 20, atol=0.5 * 0.002 + 1e-9)
    assert threads == {"robogest-video-encoder"}, "encoding overlaps the next frame's rendering"
    assert stats.frames == rep.n_video_frames and stats.render_s > 0 and stats.encode_s > 0
    with av.open(str(out)) as c:
        assert c.streams.video[0].frames == rep.n_video_frames


@pytest.mark.slow
def test_speak_video_at_the_renderers_default_size_says_so(tmp_path, capsys):
    """No --video-size: the size the renderer calls for (640x360 on a software one), said before rendering."""
    from robogest.cli.main import main

    out = tmp_path / "v.mp4"
    auto = _needs_renderer(render.video_settings)
    assert main(["speak", "Hi.", "--video", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"video: rendering {auto.width}x{auto.height} at 25 fps on {auto.renderer}" in said
    with av.open(str(out)) as c:
        ctx = c.streams.video[0].codec_context
        assert (ctx.width, ctx.height) == (auto.width, auto.height)
    if auto.cheap:
        assert (auto.width, auto.height) == (640, 360) and "--video-size 1280x720 for full size" in said
