"""Streaming generation: speech that is still arriving -> joint targets for the control loop.

:class:`StreamingPlanner` is a thin incremental wrapper around a batch :class:`~robogest.generators.Generator`
(the default ``rhythm``): after every front-end update it calls ``generate`` on the speech received so far
(:meth:`SpeechStream.speech`, padded so the generator does not retract to rest at the provisional end), keeps
the frames up to ``received - L`` that it has not sent yet, retargets just those (IK warm-started from the last
frame sent) and appends them to a :class:`TrajectoryFeed`, which the control loop plays like a trajectory.
Frames already sent are never changed: when a newly found beat changes the plan, the new frames are blended
from the old ones over ``blend_s``. Strokes still land on beats because the motion is played L behind the
newest audio, and the speech audio is delayed by the same L.

Learned generators stay batch-only (they need the whole utterance's features); the streaming path uses
``rhythm``.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from robogest.generators.base import Generator
from robogest.motion.human_motion import HumanMotion
from robogest.robot.config import RobotConfig
from robogest.speech.stream import SpeechStream
from robogest.trajectory import Trajectory

#: Seconds of assumed speech appended to a partial utterance before generating (see module docstring).
PAD_S = 1.5


class TrajectoryFeed:
    """A trajectory that grows while it plays: what :meth:`ControlLoop.play` needs of a :class:`Trajectory`.

    Until :meth:`close`, :attr:`duration_s` is infinite and sampling past the last frame holds it (an
    *underrun*, counted). Frames are ``(J,)`` radians at ``fps``.
    """

    def __init__(self, robot: RobotConfig, fps: float) -> None:
        self.joint_names = list(robot.joint_names)
        self.robot = robot.name
        self.fps = float(fps)
        self._robot = robot
        # the limits it was made for, as a Trajectory carries them (the control loop checks they are the robot's)
        self.q_min_rad, self.q_max_rad = robot.q_min_rad, robot.q_max_rad
        self.v_max_rad_s, self.a_max_rad_s2, self.rest_q_rad = robot.v_max_rad_s, robot.a_max_rad_s2, robot.rest_q_rad
        self._q = np.empty((0, len(self.joint_names)))
        self._lock = threading.Lock()
        self.closed = False
        self.underruns = 0

    @property
    def n_frames(self) -> int:
        return int(self._q.shape[0])

    @property
    def q_rad(self) -> np.ndarray:
        """Frames so far ``(K, J)``, radians."""
        return self._q

    @property
    def known_s(self) -> float:
        """Time of the last frame, seconds (-1/fps when empty)."""
        return (self.n_frames - 1) / self.fps

    @property
    def duration_s(self) -> float:
        return self.known_s if self.closed else math.inf

    def append(self, q_rad: np.ndarray) -> None:
        """Frames ``(K, J)`` radians, continuing the feed."""
        q_rad = np.asarray(q_rad, float).reshape(-1, len(self.joint_names))
        with self._lock:
            self._q = np.concatenate([self._q, q_rad])

    def close(self) -> None:
        self.closed = True

    def sample(self, t_s: float) -> np.ndarray:
        """Pose ``(J,)`` radians at ``t_s`` (linear between frames; the last frame once past it)."""
        q = self._q
        x = max(0.0, t_s) * self.fps
        i = int(x)
        if i >= q.shape[0] - 1:
            if not self.closed and t_s > self.known_s + 0.5 / self.fps:
                self.underruns += 1
            return q[-1].copy()
        f = x - i
        return (1 - f) * q[i] + f * q[i + 1]

    def sample_velocity(self, t_s: float) -> np.ndarray:
        """Slope ``(J,)`` rad/s of :meth:`sample` at ``t_s`` (0 outside the frames)."""
        q = self._q
        i = int(max(0.0, t_s) * self.fps)
        if t_s < 0 or i >= q.shape[0] - 1:
            return np.zeros(q.shape[1])
        return (q[i + 1] - q[i]) * self.fps

    def to_trajectory(self) -> Trajectory:
        """The frames so far as a :class:`Trajectory` (for checks and saving)."""
        r = self._robot
        n = self.n_frames
        return Trajectory(
            t_s=np.arange(n) / self.fps, q_rad=self._q.copy(), joint_names=self.joint_names,
            q_min_rad=r.q_min_rad, q_max_rad=r.q_max_rad, v_max_rad_s=r.v_max_rad_s, a_max_rad_s2=r.a_max_rad_s2,
            rest_q_rad=r.rest_q_rad, silent=np.zeros(n, bool), robot=r.name,
        )  # fmt: skip


def _min_jerk(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x * x)


class StreamingPlanner:
    """Plans one streamed utterance incrementally (see module docstring).

    Parameters
    ----------
    robot : RobotConfig
    generator : Generator
        A generator that works on partial speech (``rhythm``).
    retargeter : Retargeter
        The session's IK.
    stream : SpeechStream
    fps : float
        Frame rate of the feed, frames/s.
    seed : int
    blend_s : float
        Replanned frames blend from the previous plan over this long, seconds.
    """

    def __init__(
        self,
        robot: RobotConfig,
        generator: Generator,
        retargeter,
        stream: SpeechStream,
        fps: float = 50.0,
        seed: int = 0,
        blend_s: float = 0.25,
    ) -> None:
        self.robot = robot
        self.generator = generator
        self.ik = retargeter
        self.stream = stream
        self.seed = seed
        self.blend_s = blend_s
        self.feed = TrajectoryFeed(robot, fps)
        self.rest = np.asarray(robot.rest_q_rad, float)
        self.lo = robot.q_min_rad + 0.02
        self.hi = robot.q_max_rad - 0.02
        self._q_last = self.rest.copy()
        self.n_plans = 0
        #: Human-motion frames sent, one segment per plan (the canonical-skeleton side, for evaluation).
        self.human_segments: list[HumanMotion] = []

    def plan(self) -> int:
        """Extend the feed with every frame the stream now allows; returns how many were added."""
        st, feed = self.stream, self.feed
        final = st.closed
        speech = st.speech(pad_s=PAD_S)
        if speech.n_frames < 2:
            return 0
        motion = self.generator.generate(speech, seed=self.seed).resample(feed.fps)
        upto_s = speech.duration_s if final else st.received_s - st.lookahead_s
        n_end = motion.n_frames if final else min(motion.n_frames, math.floor(upto_s * feed.fps) + 1)
        n0 = feed.n_frames
        if n_end <= n0:
            if final:
                self._finish()
            return 0
        i0 = max(0, n0 - 1)  # re-plan the last frame sent too, to see how far the new plan moved from it
        seg = HumanMotion(motion.fps, motion.rotations[i0:n_end], motion.root_pos_m[i0:n_end], motion.skeleton)
        self.human_segments.append(
            HumanMotion(motion.fps, motion.rotations[n0:n_end], motion.root_pos_m[n0:n_end], motion.skeleton)
        )
        q = self.ik.retarget(seg, q0=self._q_last).q_rad  # (K, J)
        if n0 > 0:  # frames sent are kept: the new plan starts from them and its offset decays (memoryless)
            k = np.arange(len(q))[:, None]
            q = (q + (self._q_last - q[0]) * np.exp(-k / (self.blend_s / 3 * feed.fps)))[1:]
        t = (n0 + np.arange(len(q))) / feed.fps
        rest_windows = getattr(self.generator, "rest_windows", None)
        if rest_windows is not None:  # exactly at rest where the generator rests (the silent-period hint)
            for a, b in rest_windows(speech):
                q[(t >= a) & (t <= b)] = self.rest
        q = np.clip(q, np.minimum(self.lo, self.rest), np.maximum(self.hi, self.rest))
        self._q_last = q[-1].copy()
        feed.append(q)
        self.n_plans += 1
        if final:
            self._finish()
        return len(q)

    def human_motion(self) -> HumanMotion:
        """The human motion whose frames were sent, concatenated (before IK and the joint-space blend)."""
        segs = self.human_segments
        return HumanMotion(
            self.feed.fps, np.concatenate([m.rotations for m in segs]), np.concatenate([m.root_pos_m for m in segs]),
            segs[0].skeleton,
        )  # fmt: skip

    def _finish(self) -> None:
        """End exactly at rest (a minimum-jerk glide if the generator's last frame is not), then close."""
        if self.feed.closed:
            return
        d = np.abs(self._q_last - self.rest).max()
        if d > 1e-9:
            n = max(2, math.ceil(0.6 * self.feed.fps))
            s = _min_jerk(np.arange(1, n + 1) / n)[:, None]
            self.feed.append(self._q_last + (self.rest - self._q_last) * s)
            self._q_last = self.rest.copy()
        self.feed.close()
