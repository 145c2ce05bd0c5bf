"""What a simulated run reports: how the simulated joints followed the trajectory, and where a video's time went."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.trajectory.types import Trajectory

if TYPE_CHECKING:
    from robogest.backends.player import PlaybackReport
    from robogest.backends.recorder import VideoRecorder


@dataclass
class SimReport:
    """How the simulated servos followed a trajectory.

    Attributes
    ----------
    t_s : ndarray [shape=(T,)], seconds
        The trajectory's sample times.
    q_cmd_rad, q_achieved_rad : ndarray [shape=(T, J)], radians
        Commanded and simulated joint angles at those times (trajectory joint order).
    joint_names : list of str, length J
    tracking_rms_deg : ndarray [shape=(J,)], degrees
        RMS of achieved - commanded per joint.
    tracking_rms_deg_overall : float, degrees
        RMS over every joint and sample.
    max_abs_error_deg : float, degrees
        Largest absolute tracking error.
    self_collision_s : float, seconds
        Simulated time during which two robot parts touched.
    video_path : Path or None
    n_video_frames : int
    render_s_per_frame : float, seconds
        Mean rendering (not encoding) time per video frame; 0 without video.
    wall_s : float, seconds
        Wall-clock time of the whole run.
    extra : dict
        ``playback``: the player's report; with a video, ``video`` (:class:`~robogest.backends.recorder.VideoStats`,
        where its time went) and ``video_settings`` (size, options, renderer).
    """

    t_s: np.ndarray
    q_cmd_rad: np.ndarray
    q_achieved_rad: np.ndarray
    joint_names: list[str]
    tracking_rms_deg: np.ndarray
    tracking_rms_deg_overall: float
    max_abs_error_deg: float
    self_collision_s: float = 0.0
    video_path: Path | None = None
    n_video_frames: int = 0
    render_s_per_frame: float = 0.0
    wall_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> str:
        """A few human-readable lines."""
        head = f"tracking RMS {self.tracking_rms_deg_overall:.2f} deg overall"
        head += f", max |error| {self.max_abs_error_deg:.2f} deg"
        if self.joint_names:
            w = int(np.argmax(self.tracking_rms_deg))
            head += f", worst joint {self.joint_names[w]} ({self.tracking_rms_deg[w]:.2f} deg RMS)"
        lines = [head, f"self-collision {self.self_collision_s:.2f} s"]
        if self.video_path is not None:
            lines.append(
                f"video {self.video_path} ({self.n_video_frames} frames, {1000 * self.render_s_per_frame:.0f} ms/frame)"
            )
        return "\n".join(lines)


def tracking_report(
    trajectory: Trajectory,
    played: Trajectory,
    log: dict[str, np.ndarray],
    playback: PlaybackReport,
    self_collision_s: float,
    video: VideoRecorder | None,
    video_path: Path | None,
    t_wall0: float,
) -> SimReport:
    """Compare ``trajectory`` (its ``T`` frames; ``played`` is it in the robot's joint order, held to the audio's
    end) with the simulated joints' ``log`` (``t_s`` ``(N,)``, ``q_rad`` ``(N, J)``) sampled at the same times."""
    t0 = playback.ramp_in_s  # simulated time at which trajectory time 0 was played (0: the sim starts there)
    n = trajectory.n_frames
    q_cmd = played.q_rad[:n]
    q_ach = np.stack([np.interp(played.t_s[:n] + t0, log["t_s"], log["q_rad"][:, j]) for j in range(q_cmd.shape[1])], 1)
    err_deg = np.degrees(q_ach - q_cmd)
    rms = np.sqrt(np.mean(err_deg**2, axis=0)) if len(err_deg) else np.zeros(q_cmd.shape[1])
    n_frames = video.n_frames if video is not None else 0
    extra: dict[str, Any] = {"playback": playback}
    render_s = 0.0
    if video is not None:
        extra |= {"video": video.stats, "video_settings": video.settings}
        render_s = (video.stats.scene_s + video.stats.render_s) / n_frames if n_frames else 0.0
    return SimReport(
        t_s=played.t_s[:n].copy(),
        q_cmd_rad=q_cmd,
        q_achieved_rad=q_ach,
        joint_names=list(played.joint_names),
        tracking_rms_deg=rms,
        tracking_rms_deg_overall=float(np.sqrt(np.mean(err_deg**2))) if err_deg.size else 0.0,
        max_abs_error_deg=float(np.max(np.abs(err_deg))) if err_deg.size else 0.0,
        self_collision_s=self_collision_s,
        video_path=video_path,
        n_video_frames=n_frames,
        render_s_per_frame=render_s,
        wall_s=time.perf_counter() - t_wall0,
        extra=extra,
    )
