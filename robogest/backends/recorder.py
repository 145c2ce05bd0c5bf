"""What watches a simulation: the interactive viewer (:class:`ViewerObserver`) and its video, a frame rendered
whenever simulated time reaches the next frame time, encoded on a second
thread.

Rendering stays in the simulation's thread (MuJoCo's GL context is current there); H.264 encoding (colour
conversion to yuv420p, libx264, muxing with the speech audio) runs on an encoder thread. MuJoCo's ``mjr_render`` and
``mjr_readPixels`` and PyAV's encoder release the GIL, so on two cores the next frame renders while the last one is
encoded. Frames keep their simulated times: the video shows the same motion whatever the machine's speed.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from robogest.backends import render as _render
from robogest.errors import MissingDependencyError, RobogestError
from robogest.media.video import VideoWriter
from robogest.robot.config import RobotConfig

#: Frames waiting for the encoder at most: enough to ride out a slow frame, little memory (2.7 MB a 720p frame).
QUEUE_FRAMES = 4


@dataclass
class VideoStats:
    """Where a video's time went, seconds (wall clock): ``scene_s`` building the scene, ``render_s`` rendering and
    reading back the pixels (main thread), ``encode_s`` encoding and muxing (encoder thread), ``wait_s`` the main
    thread waiting for a full encoder queue; and ``frame_times_s``, each frame's simulated time (k / fps, to within
    half a physics step)."""

    frames: int = 0
    scene_s: float = 0.0
    render_s: float = 0.0
    encode_s: float = 0.0
    wait_s: float = 0.0
    frame_times_s: list[float] = field(default_factory=list)

    def as_dict(self) -> dict[str, float]:
        return {"frames": self.frames, "scene_s": self.scene_s, "render_s": self.render_s,
                "encode_s": self.encode_s, "wait_s": self.wait_s}  # fmt: skip


class VideoRecorder:
    """Renders the scene at every video frame time and streams the frames into an MP4 (a
    :attr:`~robogest.backends.mujoco_sim.MujocoBackend.observers` entry: call it after every physics step).

    Parameters
    ----------
    model, data : the simulation's; ``data`` is rendered as it is at each frame time.
    robot : RobotConfig
        For the framing camera of a scene without one of its own.
    path : str or Path
        Output ``.mp4``, written atomically (see :class:`~robogest.media.video.VideoWriter`).
    settings : VideoSettings
        Frame size and render options (:func:`~robogest.backends.render.video_settings`).
    fps : int
        Video frame rate (frames at t = 0, 1/fps, 2/fps, ... of simulated time).
    audio : ndarray [shape=(N,) or (N, C)], optional
        Speech to mux in, at ``audio_sr`` Hz.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        robot: RobotConfig,
        path: str | Path,
        settings: _render.VideoSettings,
        fps: int = 25,
        audio: np.ndarray | None = None,
        audio_sr: int = 16000,
    ) -> None:
        w, h = settings.width, settings.height
        self.settings = settings
        self.stats = VideoStats()
        self.writer = VideoWriter(path, w, h, fps, audio, audio_sr)
        self.frame_dt = 1.0 / fps
        self.half_step = 0.5 * float(model.opt.timestep)
        self.next_t = 0.0
        self._queue: queue.Queue[np.ndarray | None] = queue.Queue(maxsize=QUEUE_FRAMES)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._encode_loop, name="robogest-video-encoder", daemon=True)
        self.renderer: mujoco.Renderer | None = None
        try:
            self.renderer = _render.make_renderer(model, w, h, cheap=settings.cheap)
            self.cam = _render.video_camera(model, data, robot, w, h)
            self._thread.start()
            self(model, data)  # the frame at t = 0
        except BaseException:
            self.abort()
            self.release()
            raise

    @property
    def n_frames(self) -> int:
        """Frames rendered so far (all of them are in the file once :meth:`close` returns)."""
        return self.stats.frames

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if data.time < self.next_t - self.half_step:
            return
        self._raise_if_failed()
        if self.renderer is None:
            raise RobogestError("the video recorder was released; no more frames can be rendered")
        self.stats.frame_times_s.append(float(data.time))
        t0 = time.perf_counter()
        self.renderer.update_scene(data, camera=self.cam)
        t1 = time.perf_counter()
        rgb = self.renderer.render()
        t2 = time.perf_counter()
        self._queue.put(rgb)  # blocks while the encoder is QUEUE_FRAMES behind
        self.stats.scene_s += t1 - t0
        self.stats.render_s += t2 - t1
        self.stats.wait_s += time.perf_counter() - t2
        self.stats.frames += 1
        self.next_t += self.frame_dt

    def _encode_loop(self) -> None:
        while (rgb := self._queue.get()) is not None:
            if self._error is not None:
                continue  # drain: the file is already dropped
            t0 = time.perf_counter()
            try:
                self.writer.add_frame(rgb)
            except BaseException as e:  # raised again in the simulation's thread
                self._error = e
            self.stats.encode_s += time.perf_counter() - t0

    def _raise_if_failed(self) -> None:
        """Raise, in the caller's thread, what stopped the encoder (a full disk: one line, the file dropped)."""
        e = self._error
        if e is not None:
            raise type(e)(str(e)) if isinstance(e, RobogestError) else e

    def _stop_encoder(self) -> None:
        """Let the encoder finish the queued frames and end; idempotent."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()

    def close(self) -> Path:
        """Encode the remaining frames, flush, and move the finished file into place; returns its path."""
        self._stop_encoder()
        self._raise_if_failed()
        return self.writer.close()

    def abort(self) -> None:
        """Stop encoding and drop the partial file."""
        self._error = self._error or RobogestError("video writing was stopped")
        self._stop_encoder()
        self.writer.abort()

    def release(self) -> None:
        """Free the GL context (after :meth:`close` or :meth:`abort`); idempotent."""
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None


class ViewerObserver:
    """The interactive viewer, synced at about 60 Hz of simulated time; closing it only stops the display."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        from mujoco import viewer as mj_viewer

        try:
            self.viewer = mj_viewer.launch_passive(model, data)
        except Exception as e:
            raise MissingDependencyError(f"cannot open the MuJoCo viewer ({e}); is a display available?") from None
        self.next_t = 0.0

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if data.time >= self.next_t and self.viewer.is_running():
            self.viewer.sync()
            self.next_t = data.time + 1.0 / 60.0
