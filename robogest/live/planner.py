"""Streaming generation: speech that is still arriving -> joint targets for the control loop.

:class:`StreamingPlanner` is a thin incremental wrapper around a batch :class:`~robogest.generators.Generator`
(the default ``rhythm``). After every front-end update it calls ``generate`` on the speech received so far
(:meth:`SpeechStream.speech`, padded so the generator does not retract to rest at the provisional end) and
writes the frames up to ``received + ahead_s`` into a :class:`TrajectoryFeed`, which the control loop plays like
a trajectory, L behind the newest audio (the speech audio is delayed by the same L).

Frames are *provisional* until the control loop samples them: a later plan that sees a new beat rewrites the
frames not yet played (blended from the last frame kept, so the target never jumps), and frames already played
are never changed. The feed always holds a few hundred milliseconds of motion beyond what is playing, so a
plan that comes late does not stall the robot.

At exactly real time a beat is heard only about 0.15 s before the frames that must move for it are played,
too late for the preparation an offline plan gives its stroke. So the planner shares a
:class:`~robogest.generators.rhythm.LivePlan` with the generator across the utterance's plans: the frames
played so far are committed (a new stroke goes straight from the held pose after them, shortened if it must
be), each word whose stressed syllable has not been heard yet is expected to bring a beat there (from the word's
timing and eSpeak NG's lexicon, :mod:`robogest.speech.stress`), and gestures the robot has started stay as placed
whatever later plans hear.

The work per plan is bounded, whatever the utterance's length: generation starts at the latest pause in which
the generator held rest (or, in speech without such a pause, a few seconds before the frames being played;
:attr:`StreamingPlanner.window_s`), and only frames whose human pose changed are retargeted.

Safety is the batch path's own :class:`~robogest.safety.stage.SafetyStage`, resumed per plan from the frame before
the plan's first (its position and step): rest pinning where the generator rests, the position band with the
margin, the fit within the limits and tracking that continues the motion already played; the end of the utterance
is the stage's way to rest. A plan the stage refuses stops the utterance (:class:`~robogest.errors.SafetyError`).

The planner asks the generator what it can do only through :attr:`Generator.capabilities`: it must declare
``streaming`` (learned generators do not: they need the whole utterance's features; the streaming path uses
``rhythm``).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time

import numpy as np

from robogest.errors import InputError, SafetyError
from robogest.generators.base import Generator, LivePlanState
from robogest.motion.human_motion import HumanMotion
from robogest.retarget.base import Retargeter
from robogest.robot.config import RobotConfig
from robogest.safety.limits import JointLimits, SafetyConfig
from robogest.safety.stage import SafetyStage
from robogest.speech.stream import SpeechStream
from robogest.trajectory import Trajectory

#: Seconds of assumed speech appended to a partial utterance before generating (see module docstring).
PAD_S = 1.5


class TrajectoryFeed:
    """A trajectory that grows, and is revised ahead of playback, while it plays.

    What :meth:`ControlLoop.play` needs of a :class:`Trajectory`. Until :meth:`close`, :attr:`duration_s` is
    infinite and sampling past the last frame holds it (an *underrun*, counted). Frames are ``(J,)`` radians at
    ``fps``. :meth:`splice` replaces the frames the player has not sampled yet; the ones it has are final.
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
        self._sampled_s = -math.inf  # latest time the player sampled
        self.closed = False
        self.underruns = 0
        self.revised = 0  #: frames rewritten by later plans before they were played

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

    @property
    def first_open(self) -> int:
        """Index of the first frame the player has not used yet: it and the later ones may still change."""
        if self._sampled_s == -math.inf:
            return 0
        return int(max(0.0, self._sampled_s) * self.fps) + 1

    def append(self, q_rad: np.ndarray) -> None:
        """Frames ``(K, J)`` radians, continuing the feed."""
        q_rad = np.asarray(q_rad, float).reshape(-1, len(self.joint_names))
        with self._lock:
            self._q = np.concatenate([self._q, q_rad])

    def splice(
        self,
        start: int,
        q_rad: np.ndarray,
        blend_s: float = 0.25,
        pinned: np.ndarray | None = None,
        continuous: bool = False,
    ) -> int:
        """Frames ``q_rad (K, J)`` radians for indices ``start..start+K-1``, replacing what is there.

        Frames the player has sampled are kept; the new ones take over from the first open frame (or the end of
        the feed, if it is shorter), offset to continue from the frame before it, the offset decaying over
        ``blend_s`` (memoryless: a minimum of motion added); ``pinned (K,)`` frames (rest) are taken as they are.
        ``continuous``: ``q_rad[0]`` already continues frame ``start - 1`` (the safety stage resumed from it), so
        no offset is added when the new frames go in at ``start``. Returns how many frames of ``q_rad`` went in.
        """
        q_rad = np.asarray(q_rad, float).reshape(-1, len(self.joint_names))
        with self._lock:
            old = self._q
            if start > old.shape[0]:  # the player ran past the last plan: the missing frames held its last pose
                fill = old[-1] if old.shape[0] else q_rad[0]
                old = np.concatenate([old, np.repeat(fill[None], start - old.shape[0], axis=0)])
            ks = min(max(start, self.first_open), old.shape[0])
            if ks - start >= q_rad.shape[0]:
                return 0
            new = q_rad[ks - start :].copy()
            if ks > 0 and not (continuous and ks == start):  # continue from the last frame kept: the offset decays
                ref = q_rad[ks - start - 1] if ks > start else new[0]
                k = np.arange(1, new.shape[0] + 1)[:, None]
                blend = (old[ks - 1] - ref) * np.exp(-k / max(1e-9, blend_s / 3 * self.fps))
                if pinned is not None:
                    blend[np.asarray(pinned, bool)[ks - start :]] = 0.0
                new += blend
            self.revised += max(0, old.shape[0] - ks)
            self._q = np.concatenate([old[:ks], new])
            return int(new.shape[0])

    def truncate(self, n_frames: int) -> None:
        """Drop the frames from ``n_frames`` on, except those the player has already used (and the first)."""
        with self._lock:
            self._q = self._q[: max(n_frames, self.first_open, 1)]

    def close(self) -> None:
        self.closed = True

    def _index(self, t_s: float) -> tuple[np.ndarray, float, int]:
        with self._lock:
            q = self._q
            if t_s > self._sampled_s:
                self._sampled_s = t_s
        x = max(0.0, t_s) * self.fps
        return q, x, int(x)

    def sample(self, t_s: float) -> np.ndarray:
        """Pose ``(J,)`` radians at ``t_s`` (linear between frames; the last frame once past it)."""
        q, x, i = self._index(t_s)
        if i >= q.shape[0] - 1:
            if not self.closed and t_s > self.known_s + 0.5 / self.fps:
                self.underruns += 1
            return np.array(q[-1], dtype=float)
        f = x - i
        return np.asarray((1 - f) * q[i] + f * q[i + 1], dtype=float)

    def sample_velocity(self, t_s: float) -> np.ndarray:
        """Slope ``(J,)`` rad/s of :meth:`sample` at ``t_s`` (0 outside the frames)."""
        q, _, i = self._index(t_s)
        if t_s < 0 or i >= q.shape[0] - 1:
            return np.zeros(q.shape[1])
        return np.asarray((q[i + 1] - q[i]) * self.fps, dtype=float)

    def to_trajectory(self) -> Trajectory:
        """The frames so far as a :class:`Trajectory` (for checks and saving)."""
        return Trajectory.for_robot(self._robot, self._q.copy(), self.fps)


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
        Revised frames blend from the last frame kept over this long, seconds.
    ahead_s : float
        Frames are planned this far beyond the newest audio received, seconds (provisional: revised by later
        plans until played), so the player never waits for a plan.
    window_s : float
        Longest stretch of speech one plan generates over, seconds, when the speech has no pause in which the
        generator rests (then it starts ``window_s / 2`` before the frames being played).
    preview : bool
        Fit each plan's new frames within the limits before tracking them
        (:func:`~robogest.safety.fit.fit_within_limits`, as the batch path does), so a stroke too fast for
        the robot is centred on its plan rather than behind it; the fit sees only the frames planned so far.

    Raises
    ------
    InputError
        A generator that does not declare ``capabilities.streaming``.
    """

    #: The stream's safety settings: the batch defaults without smoothing, which would hold each plan's last frames
    #: back for its look-ahead (``kernel // 2`` frames) and blur the splice; silent periods come as the generator's
    #: rest windows (pinned), not as a silent mask. The first plan starts still at its own first frame (the robot's
    #: pose is the control loop's; its limiter takes the robot there).
    SAFETY = SafetyConfig(smooth_kernel=1, start_from_rest=False)

    def __init__(
        self,
        robot: RobotConfig,
        generator: Generator,
        retargeter: Retargeter,
        stream: SpeechStream,
        fps: float = 50.0,
        seed: int = 0,
        blend_s: float = 0.25,
        ahead_s: float = 0.6,
        window_s: float = 8.0,
        preview: bool = True,
    ) -> None:
        caps = generator.capabilities
        if not caps.streaming:
            raise InputError(
                f"generator {generator.name!r} cannot stream (it needs the whole utterance); stream with 'rhythm' "
                "or speak the whole utterance with say()"
            )
        self.robot = robot
        self.preview = preview
        self.generator = generator
        self.ik = retargeter
        self.stream = stream
        self.seed = seed
        self.blend_s = blend_s
        self.ahead_s = ahead_s
        self.window_s = window_s
        self.feed = TrajectoryFeed(robot, fps)
        self.rest = np.asarray(robot.rest_q_rad, float)
        self.limits = JointLimits.from_robot(robot)
        self.safety_config = dataclasses.replace(self.SAFETY, preview=preview)
        self.safety = SafetyStage(self.limits, fps, self.safety_config)
        self._human = np.empty((0, 0, 4))  # (K, B, 4) human rotations behind the feed's frames: retarget changes only
        self.start_s = 0.0  #: where the current generation window starts, seconds
        self.n_plans = 0
        self.plan_s: list[float] = []  #: wall time each plan took, seconds
        #: shared with the generator across this utterance's plans, when it plans live (``rhythm``)
        self.live: LivePlanState | None = generator.new_live_plan(stream.update_s) if caps.live_plan else None

    def _window_start(self, speech_rests: list[tuple[float, float]], received_s: float) -> float:
        """Start of the generation window: a rest window already heard, or a bounded stretch back."""
        feed = self.feed
        played_s = feed.first_open / feed.fps
        start = self.start_s
        for a, b in speech_rests:  # rest windows, absolute times; the robot is exactly at rest from a to b
            if a > start and b <= received_s - self.stream.lookahead_s and a <= played_s:
                start = a
        if received_s - start > self.window_s:
            start = max(start, played_s - self.window_s / 2)
        return math.floor(start * 10 + 1e-9) / 10  # on a 0.1 s grid: whole frames of features and of the feed

    def plan(self) -> int:
        """Extend and revise the feed with every frame the stream now allows; returns how many were written."""
        t_start = time.perf_counter()
        try:
            return self._plan()
        finally:
            self.plan_s.append(time.perf_counter() - t_start)

    def _plan(self) -> int:
        st, feed = self.stream, self.feed
        final = st.closed
        full = st.speech(pad_s=PAD_S)
        if full.n_frames < 2:
            return 0
        rests = self.generator.rest_windows(full) if self.generator.capabilities.rest_windows else []
        self.start_s = self._window_start(rests, st.received_s)
        off = round(self.start_s * feed.fps)
        if self.live is not None:  # frames the player has used are final: new strokes start after them
            self.live.commit_s = feed.first_open / feed.fps
            motion = self.generator.generate_live(full.crop(self.start_s), self.live, seed=self.seed)
        else:
            motion = self.generator.generate(full.crop(self.start_s), seed=self.seed)
        motion = motion.resample(feed.fps)
        upto_s = full.duration_s if final else st.received_s + self.ahead_s
        n_end = off + motion.n_frames if final else min(off + motion.n_frames, math.floor(upto_s * feed.fps) + 1)
        d = self._first_changed(motion.rotations, off, max(off, feed.first_open), n_end)
        n = 0
        if d < n_end:
            first = max(off, d - 1)  # one frame before the change, when the window has it: the splice's reference
            seg = HumanMotion(feed.fps, motion.rotations[first - off : n_end - off],
                              motion.root_pos_m[first - off : n_end - off], motion.skeleton)  # fmt: skip
            q0 = feed.q_rad[min(first, feed.n_frames) - 1] if first > 0 and feed.n_frames else self.rest
            q = self.ik.retarget(seg, q0=q0).q_rad  # (K, J) radians, frames first..n_end-1
            t = (first + np.arange(len(q))) / feed.fps
            pinned = np.zeros(len(q), bool)
            for a, b in rests:  # exactly at rest where the generator rests (the silent-period hint)
                pinned |= (t >= a) & (t <= b)
            kept = max(first, feed.first_open)  # frames before it are played (or the reference before the change)
            if kept - first < len(q):
                q_safe = self._safe(q[kept - first :], kept, pinned[kept - first :])
                n = feed.splice(kept, q_safe, self.blend_s, pinned=pinned[kept - first :], continuous=True)
            self._remember(motion.rotations, off, first, n_end)
            self.n_plans += 1
        if final:
            self._finish(n_end)
        return n

    def _safe(self, q: np.ndarray, kept: int, pinned: np.ndarray) -> np.ndarray:
        """The IK frames ``q (K, J)`` for feed frames ``kept..`` (the first the player has not used) made safe by the
        stage, continuing the last frame
        the player keeps (its position and step) as the batch path's tracker continues within one utterance.
        Without it the control loop's limiter saturates on raw IK frames (measured on a 16 s paragraph: goals up to
        62° from the plan, wrist-speed correlation 0.51; with it 23° and 0.90, like the batch path's 5° and 0.99).

        The result continues frame ``kept - 1`` (``splice(..., continuous=True)`` adds no offset to it). A plan the
        stage
        refuses is never replaced by the unchecked frames: the :class:`SafetyError` stops the utterance and the
        robot glides to rest, as any planner failure does."""
        feed, stage = self.feed, self.safety
        if kept == 0 or feed.n_frames == 0:  # the utterance's start: still at its first frame
            self.safety = stage = SafetyStage(self.limits, feed.fps, self.safety_config)
        else:
            ref = feed.q_rad[min(kept, feed.n_frames) - 1]  # past the end, the splice holds the last frame
            step = ref - feed.q_rad[kept - 2] if 2 <= kept <= feed.n_frames else np.zeros_like(ref)
            stage.resume(ref, step, kept - 1)
        try:
            return stage.extend(q, pinned=pinned)
        except SafetyError as e:
            raise SafetyError(
                f"safety: streamed plan {self.n_plans + 1} (frames from {kept / feed.fps:.2f} s) cannot continue "
                f"the motion within the robot's limits, so the utterance stops and the robot glides to rest: {e}"
            ) from e

    def _remember(self, rot: np.ndarray, off: int, first: int, n_end: int) -> None:
        """Keep the human poses behind frames ``first..n_end-1`` (``rot`` starts at frame ``off``)."""
        h = self._human if self._human.shape[0] else rot[:0]
        if h.shape[0] < first:  # the player ran past the plan (an underrun): those frames are final anyway
            h = np.concatenate([h, np.repeat(rot[first - off][None], first - h.shape[0], axis=0)])
        self._human = np.concatenate([h[:first], rot[first - off : n_end - off]])

    def _first_changed(self, rot: np.ndarray, off: int, k0: int, n_end: int) -> int:
        """First frame index in ``k0..n_end-1`` whose human pose differs from the last plan's (n_end: none)."""
        n_old = min(n_end, self._human.shape[0]) - k0
        if n_old <= 0:
            return k0
        diff = np.abs(self._human[k0 : k0 + n_old] - rot[k0 - off : k0 - off + n_old]) > 1e-12
        changed = diff.reshape(n_old, -1).any(axis=1)
        return k0 + int(np.argmax(changed)) if changed.any() else k0 + n_old

    def _finish(self, n_end: int) -> None:
        """End exactly at rest (a minimum-jerk glide if the generator's last frame is not, made safe by the stage
        like every plan, and the stage's way to rest if that does not arrive still), then close."""
        feed = self.feed
        if feed.closed:
            return
        feed.truncate(n_end)  # provisional frames planned past the end of the speech
        q = feed.q_rad
        if q.shape[0]:
            last = q[-1]
            self.safety.resume(last, last - q[-2] if q.shape[0] >= 2 else np.zeros_like(last), q.shape[0] - 1)
            if np.abs(last - self.rest).max() > 1e-9:
                n = max(2, math.ceil(0.6 * feed.fps))
                s = _min_jerk(np.arange(1, n + 1) / n)[:, None]
                feed.append(self.safety.extend(last + (self.rest - last) * s, pinned=np.arange(n) == n - 1))
            feed.append(self.safety.finish())
        feed.close()


def _min_jerk(x: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile ``(N,)`` from 0 to 1 over ``x`` in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.asarray(x**3 * (10 - 15 * x + 6 * x * x), dtype=float)
