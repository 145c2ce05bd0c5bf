"""A live robot session: one connection, many utterances, idle motion in between, interruption.

:class:`Robot` owns one :class:`~robogest.backends.control.ControlLoop` (the one player: every goal passes its
online position/velocity/acceleration/jerk limiter) for its whole life. Torque goes on when the session opens
and stays on between utterances, holding rest or playing the idle motion; it goes off only when the session
closes, on an unrecoverable backend error (a servo lost, in error or found limp, also between utterances: the next
call raises it), or on SIGINT/SIGTERM/SIGHUP/SIGQUIT, always after the glide to rest.

Utterances:

* :meth:`Robot.say` - text (eSpeak NG) or an audio file: the batch pipeline (speech -> ``rhythm`` or a
  learned generator -> IK -> safety layer) makes a trajectory, the loop plays it;
* :meth:`Robot.stream` - PCM chunks from a voice agent: :class:`~robogest.speech.stream.SpeechStream` +
  :class:`~robogest.live.planner.StreamingPlanner` extend a trajectory while it plays, L seconds behind the
  newest audio; the speech audio is delayed by the same L.

Every utterance returns an :class:`UtteranceHandle` whose :attr:`~UtteranceHandle.events` are dicts with
``type`` and ``t_monotonic_s`` (``time.monotonic()``).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import queue
import sys
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robogest.backends.audio import AudioOut, open_output
from robogest.errors import InputError
from robogest.live import claims
from robogest.live.idle import IdleConfig, IdleMotion
from robogest.live.prepare import WARM_UP_TEXT, ProcessPreparer, SayPreparer, SayRequest, generator_key
from robogest.live.style import BodyLanguage, body_language
from robogest.live.worker import Worker
from robogest.robot.registry import DEFAULT_ROBOT

#: Event types an utterance can report, in the order they usually happen.
EVENT_TYPES = ("requested", "first_chunk", "first_goal", "started", "audio_start", "done", "interrupted", "error")
_ids = itertools.count(1)


class UtteranceHandle:
    """One utterance given to a :class:`Robot`: its events, and a way to wait for it.

    ``events``: dicts with ``type`` (see :data:`EVENT_TYPES`; also ``audio_chunk`` when the session cannot
    play audio itself: ``offset_s`` into the utterance and the ``t_monotonic_s`` it should start playing) and
    ``t_monotonic_s``; ``first_goal`` is the first goal sent that departs from the pose held before.
    """

    def __init__(self, kind: str) -> None:
        self.id = next(_ids)
        self.kind = kind
        self._own: list[dict] = []
        self._lock = threading.Lock()
        self._attached = threading.Event()
        self._play: Any = None
        self._abandoned = False
        self._error: BaseException | None = None
        self.trajectory: Any = None  #: the Trajectory played (or the growing feed of a stream)

    def _add(self, type_: str, t: float | None = None, **extra: Any) -> None:
        with self._lock:
            self._own.append({"type": type_, "t_monotonic_s": time.monotonic() if t is None else t, **extra})

    def _attach(self, play: Any) -> None:
        self._play = play
        self._attached.set()

    def _abandon(self, why: str) -> None:
        """Nothing will be played (e.g. interrupted before the first motion was planned; the caller resumes idle)."""
        with self._lock:
            if self._abandoned:  # once (an interrupt finishes a say being prepared, whose worker then gives up too)
                return
        self._abandoned = True
        self._add("interrupted", reason=why)
        self._attached.set()

    def _fail(self, e: BaseException) -> None:
        """Its preparation failed: an ``error`` event (``message``), :meth:`wait` raises ``e``; nothing plays."""
        self._error = e
        self._abandoned = True
        self._add("error", message=str(e) or type(e).__name__)
        self._attached.set()

    @property
    def error(self) -> BaseException | None:
        """Why the utterance could not be prepared (bad input, unknown gesture tag...), or None."""
        return self._error

    @property
    def events(self) -> list[dict]:
        """All events so far, ordered by time."""
        with self._lock:
            out = list(self._own)
        if self._play is not None:
            for name, ev in list(self._play.events.items()):
                out.append({"type": name, "t_monotonic_s": ev.monotonic_s})
        return sorted(out, key=lambda e: e["t_monotonic_s"])

    def event(self, type_: str) -> dict | None:
        """The first event of ``type_``, or None."""
        return next((e for e in self.events if e["type"] == type_), None)

    @property
    def done(self) -> bool:
        """Finished: played to the end, interrupted, or failed."""
        return self._abandoned or (self._play is not None and self._play.done)

    @property
    def interrupted(self) -> bool:
        return self.event("interrupted") is not None

    def wait_started(self, timeout_s: float | None = None) -> bool:
        """Block until the utterance is prepared and handed to the robot, or abandoned (False on ``timeout_s``);
        raises its preparation's failure."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        step = 0.05  # short waits: signals reach the main thread between them
        while not self._attached.wait(step if deadline is None else max(0.0, min(step, deadline - time.monotonic()))):
            if deadline is not None and time.monotonic() >= deadline:
                return False
        if self._error is not None:
            raise self._error
        return True

    @property
    def prepared(self) -> bool:
        """Handed to the robot, abandoned or failed: :meth:`wait_started` would return at once."""
        return self._attached.is_set()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until :attr:`done` (or ``timeout_s``); raises a failure of its preparation or of the backend.
        Returns :attr:`done`."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        if not self.wait_started(timeout_s):
            return False
        if self._play is None:
            return True
        left = None if deadline is None else max(0.0, deadline - time.monotonic())
        return bool(self._play.wait(left))


class Robot:
    """A robot that stays connected: say things, stream speech, interrupt, idle in between.

    Parameters
    ----------
    name : str
        Robot name (``robogest robots list``) or YAML path.
    backend : str
        ``sim`` (MuJoCo, paced in real time), ``dynamixel`` or ``feetech``.
    port : str, optional
        Serial port of a servo backend (default: the robot YAML's ``bus.port``).
    idle : bool
        Breathing and weight shift between utterances (:mod:`robogest.live.idle`); False holds rest.
    idle_config : IdleConfig, optional
        Rate and amplitude of the idle motion.
    generator : str
        Gesture generator for :meth:`say` (learned ones need ``checkpoint`` in ``generator_options``).
        Streaming always uses ``rhythm``: learned generators are batch-only.
    seed : int
        Seed of the gesture choices.
    lookahead_s : float
        L of streamed speech, seconds (motion and audio are played this far behind the newest chunk).
    rate_hz : float
        Control-loop rate, Hz.
    time_scale : float
        Loop seconds per wall second (tests run faster than real time with > 1; audio is then not played).
    audio : bool
        Play speech through ``sounddevice`` when it and an output device exist.
    voice, words_per_minute : str, int
        eSpeak NG voice and rate for text.
    baudrate : int, optional
        Baud rate of a servo backend.
    on_tick : callable (loop_s, goal_rad), optional
        Called after every control tick with the goal ``(J,)`` radians sent (keep it short).
    backend_options : dict, optional
        More keyword options of the backend (e.g. ``lost_after_s`` of a servo backend).
    warm_up : bool
        Run the speech (eSpeak NG, the front-end) and planning code of a say and of a stream once in the
        background after opening, so the first utterance after :attr:`ready` is nearly as fast as later ones
        (measured on the quiet 2-core machine: 424 ms to the first goal against 260 ms, docs/live.md).
    blas_threads : int or None
        While the session is open, BLAS thread pools of the whole process are limited to this many threads (the
        planner's matrices are small; more threads only take cores from the control loop: 2.5x faster streaming
        measured on 2 cores). Restored on close; None leaves them alone.
    stop_within_s : float or None
        The robot is always within this many seconds of standing at rest (every limit kept), so :meth:`interrupt`
        is at rest within it: the control loop's limiter cuts short any gesture that would take it farther (on
        humanoid_xl430, 0.45 s allows about 0.65 rad from rest at the shoulders). None: gestures as large as the
        joint limits allow, and an interrupt takes as long as the limits make it.
    approach_within_rad : float
        An utterance starting this close (every joint, radians) to the pose held starts at once, the limiter
        taking up the difference; farther away, the robot first glides to its first pose.
    prepare : str
        ``"process"``: says are prepared in a child Python process started with the session
        (:mod:`robogest.live.prepare`), so their seconds of GIL-holding work never delay the control loop or the
        caller's asyncio loop; ``"thread"``: in the session's worker thread (where child processes are unwanted;
        the same results bit for bit). Streams are planned in their own thread either way.
    """

    def __init__(
        self,
        name: str = DEFAULT_ROBOT,
        backend: str = "sim",
        port: str | None = None,
        *,
        idle: bool = True,
        idle_config: IdleConfig | None = None,
        generator: str = "rhythm",
        generator_options: dict | None = None,
        seed: int = 0,
        lookahead_s: float | None = None,
        rate_hz: float = 100.0,
        time_scale: float = 1.0,
        audio: bool = True,
        voice: str = "en-us",
        words_per_minute: int = 160,
        baudrate: int | None = None,
        on_tick: Callable[[float, np.ndarray], None] | None = None,
        backend_options: dict | None = None,
        warm_up: bool = True,
        blas_threads: int | None = 1,
        stop_within_s: float | None = 0.45,
        approach_within_rad: float = 0.2,
        prepare: str = "process",
    ) -> None:
        from robogest.robot.registry import find_robot
        from robogest.speech.stream import DEFAULT_LOOKAHEAD_S
        from robogest.tools.validate import require_followable

        self.config = find_robot(name)
        require_followable(self.config)  # a robot that cannot follow gestures would only stand there
        self.backend_name = backend
        self.port = port
        self.baudrate = baudrate
        self.idle_enabled = bool(idle)
        self.idle_config = idle_config or IdleConfig()
        self.generator_name = generator
        self.generator_options = dict(generator_options or {})
        self.seed = seed
        self.lookahead_s = DEFAULT_LOOKAHEAD_S if lookahead_s is None else float(lookahead_s)
        self.rate_hz = rate_hz
        self.time_scale = float(time_scale)
        self.want_audio = audio and self.time_scale == 1.0
        self.voice = voice
        self.words_per_minute = words_per_minute
        self.on_tick = on_tick
        self.backend_options = dict(backend_options or {})
        self.warm_up = warm_up
        self.blas_threads = blas_threads
        self.stop_within_s = stop_within_s
        self.approach_within_rad = float(approach_within_rad)
        if prepare not in ("process", "thread"):
            raise InputError(f'Robot: prepare={prepare!r}; use "process" (says prepared in a child process) or '
                             '"thread" (in the session\'s worker thread)')  # fmt: skip
        self.prepare_in = prepare
        self._preparer: SayPreparer | ProcessPreparer | None = None  #: prepares says (robogest.live.prepare)
        self._blas: Any = None
        self.loop: Any = None
        self.idle: IdleMotion | None = None
        self.audio_note = ""  #: why speech audio is not played ("" when it is)
        self._sd: Any = None
        self._exit = contextlib.ExitStack()
        self._current: UtteranceHandle | None = None
        self._audio: AudioOut | None = None
        self._opened = False
        self._say_lock = threading.Lock()
        #: One plan at a time: the planners of streams and the warm-up share one IK solver and its MuJoCo data,
        #: which two threads at once corrupt (a segfault: no glide to rest, torque left on).
        self._plan_lock = threading.Lock()
        self._interrupts = 0  #: interrupt() calls so far: an utterance asked for before one is not started after
        self._streams: weakref.WeakSet[StreamUtterance] = weakref.WeakSet()  # every stream not yet finished
        self._worker: Worker | None = None  #: gets the session ready, then prepares says (off the caller's thread)
        self._claim: tuple[str, str] | None = None  #: what this session holds (robogest.live.claims)
        self._generators: dict[tuple, Any] = {}  #: rhythm generators of per-call body language, by options
        self._preparing: set[UtteranceHandle] = set()  #: says asked for and not yet playing (under _say_lock)

    # --- life cycle --------------------------------------------------------------------------------
    def open(self) -> Robot:
        """Connect, hold the present pose with torque on, start the control loop (and the idle motion).

        Raises InputError on a session that was closed: it silently did nothing, and every ``say`` then failed as
        "not open". Make a new :class:`Robot` to connect again.
        """
        if self._opened and self.loop is not None and self.loop.closed:
            raise InputError(
                f"this {self.config.name} session was closed; a closed session is not opened again: make a new "
                "Robot(...) to connect again"
            )
        if self._opened:
            return self
        port = self.port or getattr(getattr(self.config, "bus", None), "port", None)
        key = claims.claim_key(self.backend_name, self.config.name, port)
        claims.claim(key, self)  # BackendError (one line) if this robot or port is in use here
        self._claim = key
        try:
            return self._open()
        except BaseException:
            if not self._opened:
                claims.release(key, self)
                self._claim = None
            raise

    def _open(self) -> Robot:
        from robogest.backends import get_backend_factory
        from robogest.backends.control import ControlLoop
        from robogest.generators import make_generator
        from robogest.retarget import DirectionIK

        if self.blas_threads is not None:
            from threadpoolctl import threadpool_limits

            self._blas = threadpool_limits(limits=int(self.blas_threads), user_api="blas")
        factory = get_backend_factory(self.backend_name)
        # A session runs for hours: the simulator keeps no log of its own, and keeps time with speech (the control
        # loop then ticks it on the wall clock, one period per tick, like hardware).
        opts: dict[str, object] = {"record": False, "pace": True}
        if self.backend_name != "sim":
            opts = {"port": self.port, "baudrate": self.baudrate}
        opts.update(self.backend_options)
        be = factory(self.config, **opts)
        self._ik = DirectionIK(self.config)
        self._rhythm = make_generator("rhythm")
        self._generator = (
            self._rhythm
            if self.generator_name == "rhythm" and not self.generator_options
            else make_generator(self.generator_name, **self.generator_options)
        )
        self._idle_ik = DirectionIK(self.config) if self.idle_enabled else None  # its own: built in the background
        if self.want_audio:
            self._sd, self.audio_note = open_output()
            if self.audio_note:  # one line, once per session
                print(f"robogest: speech audio is not played ({self.audio_note}); utterance events carry its "
                      "play times", file=sys.stderr)  # fmt: skip
        else:
            self.audio_note = "audio off" if self.time_scale == 1.0 else "time_scale is not 1"
        if self.prepare_in == "process":  # started by _background_start, once the loop holds the robot
            self._preparer = ProcessPreparer(self.config, self.blas_threads)
        else:
            key = generator_key(self.generator_name, self.generator_options)
            self._preparer = SayPreparer(self.config, {key: self._generator})
        self.loop = ControlLoop(
            be, self.rate_hz, threaded=True, time_scale=self.time_scale, on_tick=self.on_tick,
            stop_within_s=self.stop_within_s,
        )  # fmt: skip
        if not self.loop.wall_clock:
            from robogest.errors import BackendError

            raise BackendError(
                f"backend {self.backend_name!r} is simulated and does not keep wall-clock time; a live session plays "
                "with speech: give it backend_options={'pace': True} if it can pace"
            )
        self._opened = True
        try:
            self.loop.start()
        except BaseException:
            self.loop.close()
            self._close_preparer()
            self._opened = False  # may be opened again
            if self._blas is not None:
                self._blas.restore_original_limits()
                self._blas = None
            raise
        try:
            self._worker = Worker(self._background_start, name="robogest-warm-up")
            self._worker.start()
        except BaseException:  # e.g. a signal right here: the loop holds the robot with torque on
            self.close()
            raise
        return self

    def _background_start(self) -> None:
        """After the loop holds the robot: tabulate the idle motion (IK of its cycles) and start it, then warm up.

        Both run here so the session is ready (holding rest, taking utterances) as early as possible. The child
        process that prepares says starts first: it imports meanwhile.
        """
        if isinstance(self._preparer, ProcessPreparer):
            self._preparer.start()
        if self._idle_ik is not None:
            idle = IdleMotion(self.config, self.idle_config, retargeter=self._idle_ik)
            with self._say_lock:
                loop = self.loop
                if not loop.closed and loop.error is None and (loop.resting is None or loop.resting.done):
                    self.idle = idle
                    loop.set_idle(self._idle_target)
                else:
                    self.idle = idle  # an interrupt in progress turns it on when it reaches rest
        if self.warm_up:
            self._warm_up()

    def _holds_robot(self) -> bool:
        """Open and alive: its control loop runs (a session whose backend failed went to rest, torque off)."""
        loop = self.loop
        return bool(self._opened and loop is not None and not loop.closed and loop.error is None)

    @property
    def ready(self) -> bool:
        """Open, holding the robot, and warmed up (idle motion running, speech and planning code loaded): the
        first utterance from now on starts as fast as later ones."""
        w = self._worker
        return bool(self._holds_robot() and w is not None and w.ready.is_set())

    def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Block until :attr:`ready` (False after ``timeout_s``); raises if the session is not open or died."""
        self._check_open()
        w = self._worker
        assert w is not None
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not w.ready.wait(0.05):  # short waits: signals reach the main thread between them
            if deadline is not None and time.monotonic() >= deadline:
                return False
        self._check_open()
        return True

    def _warm_up(self) -> None:
        """Load and run the speech and planning code once (their first calls import a lot; the first eSpeak NG
        call loads its voice), for a stream and for a say (where says are prepared: this thread or the child
        process), so the first utterance starts as fast as later ones. Runs in the worker while the robot idles;
        stops early when the session closes."""
        from robogest.live.planner import StreamingPlanner
        from robogest.speech.stream import SpeechStream

        stopping = self._worker.stopping if self._worker is not None else threading.Event()
        with contextlib.suppress(Exception):
            sr = 16000
            t = np.arange(int(0.8 * sr)) / sr
            tone = (0.3 * np.sin(2 * np.pi * 180 * t) * (np.sin(2 * np.pi * 3 * t) > 0)).astype(np.float32)
            st = SpeechStream(sr, lookahead_s=self.lookahead_s)
            pl = StreamingPlanner(self.config, self._rhythm, self._ik, st)
            for i in range(0, len(tone), 1600):  # a word too: plans place its stressed syllable with eSpeak NG
                if st.feed(tone[i : i + 1600], words=[("hello", 0.1, 0.6)] if i == 0 else None):
                    with self._plan_lock:
                        pl.plan()
            st.close()
            with self._plan_lock:
                pl.plan()
        if stopping.is_set() or self._preparer is None:
            return
        with contextlib.suppress(Exception):  # (the child process has imported meanwhile)
            self._preparer.prepare(self._say_request(WARM_UP_TEXT, None, None, BodyLanguage(None, None), False))

    def close(self) -> str | None:
        """Stop any utterance, glide to rest, torque off, disconnect. Idempotent; returns why rest was not
        reached, or None."""
        if not self._opened or self.loop is None:
            return None
        with self._say_lock:
            self._cancel_locked()
        try:
            return self.loop.close()
        finally:
            self._close_preparer()  # a say being prepared there is dropped at once
            try:
                if self._worker is not None:  # joined: a thread left in numba code can crash the exit
                    self._worker.stop()
            finally:
                if self._blas is not None:
                    self._blas.restore_original_limits()
                    self._blas = None
                claims.release(self._claim, self)

    def _close_preparer(self) -> None:
        if isinstance(self._preparer, ProcessPreparer):
            self._preparer.close()

    def _release_native(self) -> None:
        """At interpreter exit, after :meth:`close`: drop the limiter's native (ruckig) objects before the
        interpreter tears the extension modules down (nanobind reports those still alive as "leaked")."""
        if self.loop is not None and self.loop.closed:
            self.loop.limiter = None

    def __enter__(self) -> Robot:
        from robogest.backends.control import signals_end_at_rest

        self._exit.enter_context(signals_end_at_rest())
        try:
            return self.open()
        except BaseException:
            self._exit.close()
            raise

    def __exit__(self, *exc: object) -> None:
        try:
            self.close()
        finally:
            self._exit.close()

    # --- idle ---------------------------------------------------------------------------------------
    def _idle_stop(self) -> None:
        """Speech is coming: the idle motion fades out now (see :meth:`IdleMotion.stop`)."""
        if self.idle is not None and self.loop is not None:
            self.idle.stop(self.loop.now_s)

    def _idle_resume(self) -> None:
        """No speech after all (refused, abandoned, interrupted): the idle motion fades in again."""
        if self.idle is not None and self.loop is not None:
            self.idle.restart(self.loop.now_s)

    def _idle_target(self, t_s: float) -> np.ndarray:
        idle = self.idle
        assert idle is not None
        last = getattr(self, "_idle_last_s", None)
        if last is None or t_s - last > 0.25:  # idle was not playing (late ticks skip less): fade in from zero
            idle.restart(t_s)
        self._idle_last_s = t_s
        return idle.target(t_s)

    # --- utterances ---------------------------------------------------------------------------------
    def _check_open(self) -> None:
        loop = self.loop
        if loop is not None and loop.error is not None:
            raise loop.error  # the backend failed: torque is already off
        if not self._opened or loop is None or loop.closed:
            raise InputError("robot session is not open (never opened, or closed); use `with Robot(...) as robot:`")

    def say(
        self,
        text: str | None = None,
        *,
        audio: str | Path | None = None,
        transcript: str | Path | None = None,
        wait: bool = True,
        lenient: bool = False,
        style: str | None = None,
        amount: float | None = None,
        gestures: str | None = None,
    ) -> UtteranceHandle:
        """Speak ``text`` (eSpeak NG) or an ``audio`` file (with an optional ``transcript``) with gestures.

        Returns at once (``wait=False``) or when the utterance is done: the speech and its motion are prepared in
        the session's worker, in the order asked; a failure there (an unreadable file, an unknown gesture tag) is
        raised by :meth:`UtteranceHandle.wait` and reported as an ``error`` event. An utterance still playing is
        replaced (its handle gets ``interrupted``; the new one starts from wherever the robot is, within every
        limit). ``style`` (calm, neutral, lively) or ``amount`` (0-2) and ``gestures`` ("auto", "none", or a folder
        or YAML file of gesture units) override the session's for this utterance only (the ``rhythm`` generator).
        Tags in ``text`` (``^start``, ``\\pau=MS\\``...: docs/animated-speech.md) are never spoken; a bad one is an
        InputError raised by ``wait``, or with ``lenient`` dropped with one logged warning.
        """
        self._check_open()
        if (text is None) == (audio is None):
            raise InputError("give either text to speak (TEXT, or --text) or --audio FILE (not both, not neither)")
        body = body_language(style, amount, gestures)
        if not body.empty and self.generator_name != "rhythm":
            raise InputError(f'say: style, amount and gestures are options of the "rhythm" generator, not '
                             f"{self.generator_name!r} (this session's)")  # fmt: skip
        h = UtteranceHandle("say")
        h._add("requested")
        with self._say_lock:
            asked = self._interrupts
            self._preparing.add(h)
        self._idle_stop()

        def drop() -> None:
            self._preparing.discard(h)
            h._abandon("session closed")

        req = self._say_request(text, audio, transcript, body, lenient)
        self._worker.submit(lambda: self._prepare(h, asked, req), drop)
        if wait:
            h.wait()
        return h

    def _say_request(
        self, text: str | None, audio: Any, transcript: Any, body: BodyLanguage, lenient: bool
    ) -> SayRequest:
        """What the preparer needs for one say: the session's options, ``body``'s overrides (``rhythm`` only)."""
        from robogest.pipeline import DEFAULT_TRAJECTORY_FPS

        name, options = self.generator_name, self.generator_options
        if not body.empty:
            name, options = "rhythm", body.options(self.generator_options)
        return SayRequest(
            text=text, audio=None if audio is None else str(audio),
            transcript=None if transcript is None else str(transcript), voice=self.voice,
            words_per_minute=self.words_per_minute, lenient=lenient, generator=name, generator_options=dict(options),
            seed=self.seed, fps=DEFAULT_TRAJECTORY_FPS,
        )  # fmt: skip

    def _prepare(self, h: UtteranceHandle, asked: int, req: SayRequest) -> None:
        """In the worker: speech, gestures, trajectory (by the preparer: here or in the child process), then play
        (unless interrupted since it was asked for)."""
        try:
            if self._interrupts != asked:  # barge-in before its turn: nothing to prepare
                h._abandon("interrupt")
                self._idle_resume()
                return
            assert self._preparer is not None
            prepared = self._preparer.prepare(req)
            h.trajectory = prepared.trajectory
            self._start(h, prepared.trajectory, lambda out: out.write(prepared.audio), prepared.sr, asked)
        except Exception as e:  # reported on the handle; the session goes on
            if not h.done:
                h._fail(e)
            self._idle_resume()
        finally:
            with self._say_lock:
                self._preparing.discard(h)

    def _generator_for(self, body: BodyLanguage) -> Any:
        """The ``rhythm`` generator of the session's options with ``body``'s overrides (kept for reuse)."""
        from robogest.generators import make_generator

        key = (body.amount, body.gestures)
        gen = self._generators.get(key)
        if gen is None:
            gen = make_generator("rhythm", **body.options(self.generator_options))
            if len(self._generators) >= 16:  # a client trying every amount must not grow it without bound
                self._generators.clear()
            self._generators[key] = gen
        return gen

    def stream(
        self,
        sample_rate: int = 16000,
        lookahead_s: float | None = None,
        *,
        style: str | None = None,
        amount: float | None = None,
        gestures: str | None = None,
    ) -> StreamUtterance:
        """A streamed utterance: ``with robot.stream(16000) as s: s.feed(chunk, words=None)``.

        ``style``/``amount``/``gestures`` as in :meth:`say`, for this stream only (streams always plan with the
        ``rhythm`` generator: the session's options when its generator is ``rhythm``, else the defaults)."""
        self._check_open()
        body = body_language(style, amount, gestures, what="stream")
        if body.empty:
            gen = self._generator if self._generator.name == "rhythm" else self._rhythm
        else:
            gen = self._generator_for(body) if self.generator_name == "rhythm" else self._rhythm_for(body)
        return StreamUtterance(
            self, int(sample_rate), self.lookahead_s if lookahead_s is None else lookahead_s, generator=gen
        )

    def _rhythm_for(self, body: BodyLanguage) -> Any:
        """A stream's ``rhythm`` generator with ``body`` when the session's own generator is a learned one."""
        from robogest.generators import make_generator

        return make_generator("rhythm", **body.options({}))

    def _start(
        self, h: UtteranceHandle, traj: Any, fill: Callable[[AudioOut], None] | None, sr: int, asked: int
    ) -> None:
        """Hand ``traj`` to the loop; audio (``fill`` writes it) starts when the trajectory does. Not if
        :meth:`interrupt` was called since the utterance was asked for (``asked``: the count then)."""
        out = AudioOut(self._sd, sr)
        if fill is not None:
            fill(out)
            out.finish()
        out.open()  # outside the control tick that starts it

        def on_start() -> None:  # in the loop's tick: keep short
            play.on_start = None  # called once: the handle kept after the utterance must not keep its audio
            played = out.start()
            h._add("audio_start", played=played)

        with self._say_lock:  # an interrupt now waits until this play is in the loop, where it stops it
            self._preparing.discard(h)
            if self._interrupts != asked:
                out.stop()
                h._abandon("interrupt")
            else:
                self._replace_audio(out)
                play = self.loop.play(traj, approach_within_rad=self.approach_within_rad)
                play.on_start = on_start
                self._current = h
                h._attach(play)
        if h._play is None:  # abandoned: the idle motion comes back
            self._idle_resume()

    def _replace_audio(self, out: AudioOut | None) -> None:
        """The caller holds ``_say_lock``: the speech audio playing stops (unless it is ``out``); ``out`` (None:
        nothing) becomes the session's."""
        if self._audio is not None and self._audio is not out:
            self._audio.stop()
        self._audio = out

    def _cancel_locked(self) -> None:
        """The caller holds ``_say_lock``: utterances asked for so far are not started (:meth:`_start`), the audio
        stops, and every unfinished stream is interrupted (lock order: ``_say_lock``, then a stream's ``_state``)."""
        self._interrupts += 1
        for h in list(self._preparing):  # done now: whoever awaits a barged-in reply hears of it at once
            h._abandon("interrupt")
        self._preparing.clear()
        self._replace_audio(None)
        for st in list(self._streams):
            st._interrupt()

    def interrupt(self, wait: bool = True) -> dict:
        """Stop speaking now and glide to rest as fast as the limits allow (idle resumes after it).

        Returns ``{"interrupt_s": t, "at_rest_s": t or None}`` (``time.monotonic()``); ``at_rest_s`` is set when
        ``wait`` (the call blocks until rest is reached).
        """
        self._check_open()
        t0 = time.monotonic()
        # Under the lock, through the glide's start: the idle motion cannot be switched on in between
        # (Robot._background_start). StreamUtterance._start takes _say_lock and its own _state one after the other,
        # never nested.
        with self._say_lock:
            self._cancel_locked()
            rest = self.loop.interrupt()

        def resume() -> None:
            try:
                rest.wait()
            except RuntimeError:  # the session closed meanwhile: its own glide took the robot to rest
                return
            with self._say_lock:  # not between a newer interrupt's check and its glide
                if self.idle is not None and not self.loop.closed and self.loop.resting is rest:
                    self._idle_resume()
                    self.loop.set_idle(self._idle_target)

        if not wait:
            threading.Thread(target=resume, daemon=True, name="robogest-resume-idle").start()
            return {"interrupt_s": t0, "at_rest_s": None}
        resume()
        return {"interrupt_s": t0, "at_rest_s": rest.events["done"].monotonic_s if "done" in rest.events else None}

    @property
    def error(self) -> BaseException | None:
        """Why the session died (the control loop failed: a servo lost, the port gone; it went to rest and turned
        torque off), or None while it lives. What a server polls to tell its clients at once."""
        loop = self.loop
        return None if loop is None else loop.error

    def status(self) -> dict:
        """Session state as plain data (what ``robogest serve`` answers to ``status``)."""
        cur = self._current
        loop = self.loop
        err = self.error
        return {
            "robot": self.config.name,
            "backend": self.backend_name,
            "open": bool(self._opened and loop is not None and not loop.closed),
            "error": None if err is None else str(err),
            "speaking": bool(cur is not None and not cur.done),
            "utterance": cur.id if cur is not None else None,
            "idle": self.idle_enabled,
            "audio": not self.audio_note,
            "audio_note": self.audio_note,
            "lookahead_s": self.lookahead_s,
            "joints": list(self.config.joint_names),
            "goal_rad": loop.goal_rad.tolist() if loop is not None and loop.limiter is not None else None,
        }


class StreamUtterance:
    """A streamed utterance (see :meth:`Robot.stream`); a context manager that closes the stream on exit.

    ``feed(chunk, words=None)``: mono int16/float32 PCM at ``sample_rate`` (10-100 ms per chunk), with optional
    word timings ``(text, start_s, end_s)`` in seconds from the utterance start. ``feed`` only checks and queues
    the chunk: the front-end and the planner run in the stream's own thread, so a voice agent's audio loop is never
    held up by planning. On leaving the block the stream is closed and the motion finishes; an exception inside
    the block interrupts the robot (glide to rest) instead. A failure in the planning thread interrupts the robot
    too, and is raised by the next ``feed``, ``close`` or ``wait``.
    """

    def __init__(self, robot: Robot, sample_rate: int, lookahead_s: float, generator: Any = None) -> None:
        from robogest.live.planner import StreamingPlanner
        from robogest.speech.stream import SpeechStream, pcm_to_float

        self.robot = robot
        self.sample_rate = sample_rate
        self._pcm = pcm_to_float
        self.speech = SpeechStream(sample_rate, lookahead_s=lookahead_s)
        gen = robot._rhythm if generator is None else generator
        self.planner = StreamingPlanner(robot.config, gen, robot._ik, self.speech, seed=robot.seed)
        self.handle = UtteranceHandle("stream")
        self.handle.trajectory = self.planner.feed
        self._out = AudioOut(robot._sd, sample_rate)
        self._out.open()  # outside the control tick that starts it
        self._chunks: list[tuple[float, int]] = []  # (offset_s, n_samples) of each chunk, for scheduling
        self._offset_n = 0
        self._t_first: float | None = None  # time.monotonic() of the first chunk: audio time 0 arrived then
        self._last_word_s = -math.inf
        self._playing = False
        self._audio_t0: float | None = None  # monotonic start of the audio when the caller must play it
        self._chunk_lock = threading.Lock()  # _chunks and _audio_t0: the caller's thread vs. the loop's
        self._dead = False
        self._closed = False
        self._error: BaseException | None = None
        self._state = threading.Lock()  # starting the motion vs. an interrupt
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"robogest-stream-{self.handle.id}")
        robot._streams.add(self)  # the utterance playing keeps its audio until this one has motion (_start)
        self._thread.start()

    def __enter__(self) -> StreamUtterance:
        return self

    def __exit__(self, et: type[BaseException] | None, *exc: object) -> None:
        if et is not None and not self._dead and self.robot.loop is not None and not self.robot.loop.closed:
            with contextlib.suppress(Exception):
                self.robot.interrupt(wait=issubclass(et, Exception))
            return
        self.close()

    def _interrupt(self) -> None:
        with self._state:
            self._dead = True
            if not self._playing and not self.handle.done:
                self._out.stop()
                self.handle._abandon("interrupt")
        self._queue.put(_STOP)

    def _raise_error(self) -> None:
        if self._error is not None:
            raise self._error

    def feed(self, chunk: np.ndarray | bytes, words: Sequence[tuple[str, float, float]] | None = None) -> None:
        """Add a chunk of speech (ignored once the utterance was interrupted); returns at once.

        Raises
        ------
        InputError
            A malformed chunk or word, a stream longer than one utterance may be, or ``feed`` after ``close``.
        """
        from robogest.speech.stream import parse_word

        self._raise_error()
        if self._dead:
            return
        if self._closed:
            raise InputError("stream: feed() after the stream was closed; open a new robot.stream()")
        a = self._pcm(chunk)
        parsed, last_s = [], self._last_word_s
        for w in words or ():
            word = parse_word(w, last_s)
            last_s = word.start_s
            parsed.append(word)
        max_s = self.speech.config.max_duration_s
        if (self._offset_n + a.shape[0]) / self.sample_rate > max_s:
            raise InputError(f"stream: longer than the maximum {max_s:.0f} s of one utterance; split it")
        if self._t_first is None:
            self._t_first = time.monotonic()
            self.handle._add("first_chunk", self._t_first)
            self.robot._idle_stop()
        off = self._offset_n / self.sample_rate
        if a.shape[0]:
            with self._chunk_lock:
                self._chunks.append((off, a.shape[0]))
                if self._audio_t0 is not None:
                    self.handle._add("audio_chunk", self._audio_t0 + off / self.robot.time_scale, offset_s=off,
                                     n_samples=a.shape[0])  # fmt: skip
        self._last_word_s = last_s  # only once the whole message is taken
        self._offset_n += a.shape[0]
        self._out.write(a)
        self._queue.put((a, parsed))

    # --- the stream's thread -----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._serve()
        finally:
            self.robot._streams.discard(self)  # planned to the end (or stopped): interrupt() stops its motion

    def _serve(self) -> None:
        try:
            while True:
                batch = [self._queue.get()]
                while not self._queue.empty():  # take everything that arrived while the last plan ran
                    batch.append(self._queue.get())
                updated = closing = False
                for item in batch:
                    if item is _STOP or self._dead:
                        return
                    if item is _CLOSE:
                        closing = True
                        break
                    updated |= self.speech.feed(*item)
                if closing:
                    self._finish()
                    return
                if updated and self._plan():
                    self._start()
        except BaseException as e:  # a bug or a bad input found late: stop the utterance, keep the session
            self._error = e
            with self._state:
                self._dead = True
                playing = self._playing
                if not playing:
                    self.handle._abandon(f"error: {e}")
            play = self.handle._play
            if playing and play is not None and not play.done:  # still what the robot plays: stop it
                with contextlib.suppress(Exception):
                    self.robot.interrupt(wait=False)
            elif not playing:  # (a stream another utterance has replaced leaves that one alone)
                self.robot._idle_resume()

    def _plan(self) -> int:
        with self.robot._plan_lock:  # the planners share the session's IK solver
            return self.planner.plan()

    def _finish(self) -> None:
        self._out.finish()  # the audio stream stops by itself once it has played the last chunk
        self.speech.close()
        self._plan()
        self.planner.feed.close()
        if self.planner.feed.n_frames:
            self._start()
            return
        with self._state:
            if self._playing or self._dead:
                return
            self.handle._abandon("no speech")
        self.robot._idle_resume()

    def _start(self) -> None:
        """The first frames exist: play them now (the audio starts with them)."""
        r = self.robot
        h = self.handle
        out = self._out
        with self._state:
            if self._playing or self._dead:
                return
            self._playing = True
            # Speech and motion play L behind the audio as it arrives (so every beat is heard before its stroke
            # plays), or later if this first plan came later.
            start_at = None
            if r.loop.wall_clock and self._t_first is not None:
                start_at = max(r.loop.now_s, r.loop.loop_s_at(self._t_first + self.speech.lookahead_s))
            try:
                play = r.loop.play(self.planner.feed, start_at=start_at, approach_within_rad=r.approach_within_rad)
            except BaseException:  # the loop failed or closed: _run abandons the handle (not playing after all)
                self._playing = False
                raise

            def on_start() -> None:  # in the loop's tick: keep short
                play.on_start = None  # called once: the handle kept after the utterance must not keep this stream
                played = out.start()
                t = time.monotonic()
                h._add("audio_start", t, played=played)
                if not played:  # the caller plays it: when each chunk should start
                    with self._chunk_lock:
                        self._audio_t0 = t
                        for off, n in self._chunks:
                            h._add("audio_chunk", t + off / r.time_scale, offset_s=off, n_samples=n)

            play.on_start = on_start
            h._attach(play)
        with r._say_lock:  # this utterance replaces the one playing: its audio stops now, not at feed time
            if self._dead:  # interrupted since the play began (interrupt() holds this lock throughout)
                out.stop()
                return
            r._replace_audio(out)
            r._current = h

    def close(self) -> UtteranceHandle:
        """No more speech: the rest is planned (ending at rest) and plays out. Returns the handle at once."""
        self._raise_error()
        if self._closed or self._dead:
            return self.handle
        self._closed = True
        self._queue.put(_CLOSE)
        return self.handle

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until the utterance is done (or ``timeout_s``); raises a failure of the planning thread."""
        done = self.handle.wait(timeout_s)
        self._raise_error()
        return done

    @property
    def events(self) -> list[dict]:
        return self.handle.events


#: Queue markers of the stream's thread.
_CLOSE, _STOP = object(), object()
