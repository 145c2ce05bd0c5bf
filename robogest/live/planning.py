"""The gesture planning a live session keeps in its own process: the IK solver and ``rhythm`` generators its
streams plan with (one plan at a time), the requests and preparer of its says (:mod:`robogest.live.prepare`), and
the warm-up of both."""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import numpy as np

from robogest.live.config import SessionConfig
from robogest.live.prepare import (
    WARM_UP_TEXT,
    GeneratorCache,
    ProcessPreparer,
    SayPreparer,
    SayRequest,
    generator_key,
)
from robogest.live.style import BodyLanguage
from robogest.robot.config import RobotConfig


class Planning:
    """What a session plans with in this process (see module docstring). Built when the session opens."""

    def __init__(self, robot: RobotConfig, options: SessionConfig, lookahead_s: float) -> None:
        from robogest.generators import make_generator
        from robogest.retarget import DirectionIK

        self.robot = robot
        self.options = options
        self.lookahead_s = lookahead_s
        self.generator_options = dict(options.generator_options)
        self.ik = DirectionIK(robot)  #: shared by the streams' planners and the warm-up
        #: One plan at a time: the planners of streams and the warm-up share one IK solver and its MuJoCo data,
        #: which two threads at once corrupt (a segfault: no glide to rest, torque left on).
        self.plan_lock = threading.Lock()
        self.rhythm = make_generator("rhythm")
        self.generator = (  #: the session's own generator
            self.rhythm
            if options.generator == "rhythm" and not self.generator_options
            else make_generator(options.generator, **self.generator_options)
        )
        self._generators = GeneratorCache()  #: rhythm generators of streams' per-call body language
        self.preparer: SayPreparer | ProcessPreparer  #: prepares says: the child process, or this one's worker
        if options.prepare == "process":  # started by start_preparer, once the loop holds the robot
            self.preparer = ProcessPreparer(robot, options.blas_threads)
        else:
            key = generator_key(options.generator, self.generator_options)
            self.preparer = SayPreparer(robot, {key: self.generator})

    def start_preparer(self) -> None:
        """Launch the child process that prepares says (it imports while the session gets ready)."""
        if isinstance(self.preparer, ProcessPreparer):
            self.preparer.start()

    def close(self) -> None:
        """End the child process (a say being prepared there is dropped at once)."""
        if isinstance(self.preparer, ProcessPreparer):
            self.preparer.close()

    def say_request(
        self, text: str | None, audio: object, transcript: object, body: BodyLanguage, lenient: bool
    ) -> SayRequest:
        """What the preparer needs for one say: the session's options, ``body``'s overrides (``rhythm`` only)."""
        from robogest.pipeline import DEFAULT_TRAJECTORY_FPS

        o = self.options
        name, options = o.generator, self.generator_options
        if not body.empty:
            name, options = "rhythm", body.options(self.generator_options)
        return SayRequest(
            text=text, audio=None if audio is None else str(audio),
            transcript=None if transcript is None else str(transcript), voice=o.voice,
            words_per_minute=o.words_per_minute, lenient=lenient, generator=name, generator_options=dict(options),
            seed=o.seed, fps=DEFAULT_TRAJECTORY_FPS,
        )  # fmt: skip

    def stream_generator(self, body: BodyLanguage) -> Any:
        """A stream's generator: always ``rhythm`` (the session's options when its generator is ``rhythm``, else
        the defaults), with ``body``'s overrides."""
        if body.empty:
            return self.generator if self.generator.name == "rhythm" else self.rhythm
        base = self.generator_options if self.options.generator == "rhythm" else {}  # a learned one's are not rhythm's
        return self._generators.get("rhythm", body.options(base))

    def warm_up(self, stopping: threading.Event) -> None:
        """Load and run the speech and planning code once (their first calls import a lot; the first eSpeak NG
        call loads its voice), for a stream and for a say (where says are prepared: this thread or the child
        process), so the first utterance starts as fast as later ones; stops early once ``stopping`` is set."""
        from robogest.live.planner import StreamingPlanner
        from robogest.speech.stream import SpeechStream

        with contextlib.suppress(Exception):
            sr = 16000
            t = np.arange(int(0.8 * sr)) / sr
            tone = (0.3 * np.sin(2 * np.pi * 180 * t) * (np.sin(2 * np.pi * 3 * t) > 0)).astype(np.float32)
            st = SpeechStream(sr, lookahead_s=self.lookahead_s)
            pl = StreamingPlanner(self.robot, self.rhythm, self.ik, st)
            for i in range(0, len(tone), 1600):  # a word too: plans place its stressed syllable with eSpeak NG
                if st.feed(tone[i : i + 1600], words=[("hello", 0.1, 0.6)] if i == 0 else None):
                    with self.plan_lock:
                        pl.plan()
            st.close()
            with self.plan_lock:
                pl.plan()
        if stopping.is_set():
            return
        with contextlib.suppress(Exception):  # (the child process has imported meanwhile)
            self.preparer.prepare(self.say_request(WARM_UP_TEXT, None, None, BodyLanguage(None, None), False))
