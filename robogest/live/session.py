"""A live robot session: one connection, many utterances, idle motion in between, interruption.

:class:`Robot` owns one :class:`~robogest.backends.control.ControlLoop` (the one player: every goal passes its
online position/velocity/acceleration/jerk limiter) for its whole life. Torque goes on when the session opens
and stays on between utterances, holding rest or playing the idle motion; it goes off only when the session
closes, on an unrecoverable backend error (a servo lost, in error or found limp, also between utterances: the next
call raises it), or on SIGINT/SIGTERM/SIGHUP/SIGQUIT, always after the glide to rest.

Utterances:

* :meth:`Robot.say` - text (eSpeak NG) or an audio file: the batch pipeline (speech -> generator -> IK -> safety
  layer; :mod:`robogest.live.prepare`, in a child process by default) makes a trajectory, the loop plays it;
* :meth:`Robot.stream` - PCM chunks from a voice agent (:mod:`robogest.live.stream`), planned while they play.

Every utterance returns an :class:`~robogest.live.utterance.UtteranceHandle`. Options: :class:`SessionConfig`. What
plays, the says being prepared and the audio are changed only in the session's owner thread (:mod:`.owner`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
import threading
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robogest.errors import InputError
from robogest.live import claims
from robogest.live.config import SessionConfig
from robogest.live.idle import IdleConfig, IdleMotion
from robogest.live.idle_control import IdlePlayer
from robogest.live.owner import Owner
from robogest.live.planning import Planning
from robogest.live.prepare import SayRequest
from robogest.live.stream import StreamUtterance
from robogest.live.style import body_language
from robogest.live.utterance import EVENT_TYPES, UtteranceHandle
from robogest.live.worker import Worker
from robogest.media.audio import AudioOut, open_output

if TYPE_CHECKING:
    from robogest.backends.control import ControlLoop, PlayHandle
    from robogest.trajectory import Trajectory
from robogest.robot.registry import DEFAULT_ROBOT


class Robot:
    """A robot that stays connected: say things, stream speech, interrupt, idle in between.

    ``Robot(name, backend, port, **options)`` or ``Robot(name, config=SessionConfig(...))`` (keywords given too
    override its fields); the options are the fields of :class:`~robogest.live.config.SessionConfig`, checked
    when the session is made (an InputError names the bad one).

    ``name``: a robot name (``robogest robots list``) or YAML path.
    """

    def __init__(
        self,
        name: str = DEFAULT_ROBOT,
        backend: str | None = None,
        port: str | None = None,
        *,
        config: SessionConfig | None = None,
        **options: Any,
    ) -> None:
        from robogest.robot.registry import find_robot
        from robogest.speech.stream import DEFAULT_LOOKAHEAD_S
        from robogest.tools.validate import require_followable

        if backend is not None:
            options["backend"] = backend
        if port is not None:
            options["port"] = port
        base = {} if config is None else {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
        cfg = SessionConfig.from_options(**{**base, **options})  # the keywords override ``config``'s
        self.options = cfg  #: the session's options
        self.config = find_robot(name)  #: the robot
        require_followable(self.config)  # a robot that cannot follow gestures would only stand there
        # the options read most (and by callers), as attributes; the rest are read from self.options
        self.backend_name, self.seed, self.stop_within_s = cfg.backend, cfg.seed, cfg.stop_within_s
        self.idle_enabled, self.idle_config = bool(cfg.idle), cfg.idle_config or IdleConfig()
        self.lookahead_s = DEFAULT_LOOKAHEAD_S if cfg.lookahead_s is None else float(cfg.lookahead_s)
        self.time_scale = float(cfg.time_scale)
        self.want_audio = cfg.audio and self.time_scale == 1.0
        self.approach_within_rad = float(cfg.approach_within_rad)
        self.planning: Planning | None = None  #: IK, generators and the say preparer (made by open())
        self._blas: Any = None
        self.loop: ControlLoop | None = None
        self.idle: IdlePlayer | None = None  #: the idle motion, once tabulated (robogest.live.idle_control)
        self.audio_note = ""  #: why speech audio is not played ("" when it is)
        self.audio_device: Any = None  #: the ``sounddevice`` module speech plays through (None: not played)
        self._exit = contextlib.ExitStack()
        self._opened = False
        self._worker: Worker | None = None  #: gets the session ready, then prepares says (off the caller's thread)
        self._claim: tuple[str, str] | None = None  #: what this session holds (robogest.live.claims)
        # The utterance state, owned by one thread (robogest.live.owner): changed only by messages run there.
        self._owner = Owner("robogest-session")
        self._current: UtteranceHandle | None = None  #: the utterance playing last (read by status())
        self._audio: AudioOut | None = None  #: the speech audio playing
        self._preparing: set[UtteranceHandle] = set()  #: says asked for and not yet playing
        self._streams: weakref.WeakSet[StreamUtterance] = weakref.WeakSet()  #: every stream not yet finished

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
        port = self.options.port or getattr(getattr(self.config, "bus", None), "port", None)
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
        from robogest.retarget import DirectionIK

        if self.options.blas_threads is not None:
            from threadpoolctl import threadpool_limits

            self._blas = threadpool_limits(limits=int(self.options.blas_threads), user_api="blas")
        factory = get_backend_factory(self.backend_name)
        # A session runs for hours: the simulator keeps no log of its own, and keeps time with speech (the control
        # loop ticks every backend on the wall clock: a simulator one period per tick, paced like hardware).
        opts: dict[str, object] = {"record": False, "pace": True}
        if self.backend_name != "sim":
            opts = {"port": self.options.port, "baudrate": self.options.baudrate}
        opts.update(self.options.backend_options)
        be = factory(self.config, **opts)
        self.planning = Planning(self.config, self.options, self.lookahead_s)
        self._idle_ik = DirectionIK(self.config) if self.idle_enabled else None  # its own: built in the background
        if self.want_audio:
            self.audio_device, self.audio_note = open_output()
            if self.audio_note:  # one line, once per session
                print(f"robogest: speech audio is not played ({self.audio_note}); utterance events carry its "
                      "play times", file=sys.stderr)  # fmt: skip
        else:
            self.audio_note = "audio off" if self.time_scale == 1.0 else "time_scale is not 1"
        self.loop = ControlLoop(
            be, self.options.rate_hz, threaded=True, wall_clock=True, time_scale=self.time_scale,
            on_tick=self.options.on_tick, stop_within_s=self.stop_within_s,
        )  # fmt: skip
        self._opened = True
        try:
            self.loop.start()
        except BaseException:
            self.loop.close()
            self._opened = False  # may be opened again
            if self._blas is not None:
                self._blas.restore_original_limits()
                self._blas = None
            raise
        try:
            self._owner.start()
            self._worker = Worker(self._background_start, name="robogest-warm-up")
            self._worker.start()
        except BaseException:  # e.g. a signal right here: the loop holds the robot with torque on
            self.close()
            raise
        return self

    def _background_start(self) -> None:
        """After the loop holds the robot (so the session takes utterances at once): start the child process that
        prepares says (it imports meanwhile), tabulate the idle motion (IK of its cycles) and start it, warm up."""
        if self.planning is not None:
            self.planning.start_preparer()
        if self._idle_ik is not None:
            idle = IdleMotion(self.config, self.idle_config, retargeter=self._idle_ik)
            assert self.loop is not None  # (this runs once the loop holds the robot)
            self.idle = IdlePlayer(self.loop, idle)
            self._owner.call(self.idle.switch_on)
        if self.options.warm_up:
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
        self.check_open()
        w = self._worker
        assert w is not None
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not w.ready.wait(0.05):  # short waits: signals reach the main thread between them
            if deadline is not None and time.monotonic() >= deadline:
                return False
        self.check_open()
        return True

    def _warm_up(self) -> None:
        """Run the speech and planning code of a stream and of a say once (:meth:`Planning.warm_up`)."""
        if self.planning is not None and self._worker is not None:
            self.planning.warm_up(self._worker.stopping)

    def close(self) -> str | None:
        """Stop any utterance, glide to rest, torque off, disconnect. Idempotent; returns why rest was not
        reached, or None."""
        if not self._opened or self.loop is None:
            return None
        self._owner.call(self._cancel)
        try:
            return self.loop.close()
        finally:
            if self.planning is not None:
                self.planning.close()  # a say being prepared in the child process is dropped at once
            try:
                if self._worker is not None:  # joined: a thread left in numba code can crash the exit
                    self._worker.stop()
            finally:
                self._owner.stop()
                if self._blas is not None:
                    self._blas.restore_original_limits()
                    self._blas = None
                claims.release(self._claim, self)

    def _release_native(self) -> None:
        """At exit, after :meth:`close`: drop the limiter's native (ruckig) objects before the interpreter tears
        the extension modules down (nanobind reports those still alive as "leaked")."""
        if self.loop is not None and self.loop.closed:
            self.loop.limiter = None

    def __enter__(self) -> Robot:
        from robogest.backends.signals import signals_end_at_rest

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
        if self.idle is not None:
            self.idle.fade_out()

    def _idle_resume(self) -> None:
        """No speech after all (refused, abandoned, interrupted): the idle motion fades in again."""
        if self.idle is not None:
            self.idle.fade_in()

    # --- utterances ---------------------------------------------------------------------------------
    def check_open(self) -> ControlLoop:
        """The session's running loop; raises why there is none (the backend failed, or not open)."""
        loop = self.loop
        if loop is not None and loop.error is not None:
            raise loop.error  # the backend failed: torque is already off
        if not self._opened or loop is None or loop.closed:
            raise InputError("robot session is not open (never opened, or closed); use `with Robot(...) as robot:`")
        return loop

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

        Returns at once (``wait=False``) or when done: speech and motion are prepared by the session's worker (in
        a child process by default), in the order asked; a failure there (an unreadable file, an unknown gesture tag) is
        raised by :meth:`UtteranceHandle.wait` and reported as an ``error`` event. An utterance still playing is
        replaced (its handle gets ``interrupted``; the new one starts from wherever the robot is, within every
        limit). ``style`` (calm, neutral, lively) or ``amount`` (0-2) and ``gestures`` ("auto", "none", or a folder
        or YAML file of gesture units) override the session's for this utterance only (the ``rhythm`` generator).
        Tags in ``text`` (``^start``, ``\\pau=MS\\``...: docs/animated-speech.md) are never spoken; a bad one is an
        InputError raised by ``wait``, or with ``lenient`` dropped with one logged warning.
        """
        self.check_open()
        if (text is None) == (audio is None):
            raise InputError("give either text to speak (TEXT, or --text) or --audio FILE (not both, not neither)")
        body = body_language(style, amount, gestures)
        if not body.empty and self.options.generator != "rhythm":
            raise InputError(f'say: style, amount and gestures are options of the "rhythm" generator, not '
                             f"{self.options.generator!r} (this session's)")  # fmt: skip
        h = UtteranceHandle("say")
        h._add("requested")
        self._owner.post(lambda: self._preparing.add(h))  # (an interrupt from now on abandons it)
        self._idle_stop()
        assert self.planning is not None and self._worker is not None  # (made by open)
        req = self.planning.say_request(text, audio, transcript, body, lenient)
        self._worker.submit(lambda: self._prepare(h, req), lambda: h._abandon("session closed"))
        if wait:
            h.wait()
        return h

    def _prepare(self, h: UtteranceHandle, req: SayRequest) -> None:
        """In the worker: speech, gestures, trajectory (by the preparer: here or in the child process); the owner
        then plays it, unless interrupted since it was asked for."""
        try:
            if h.done:  # barge-in before its turn (interrupt() abandoned it): nothing to prepare
                self._idle_resume()
                return
            assert self.planning is not None
            prepared = self.planning.preparer.prepare(req)
            h.trajectory = prepared.trajectory
            out = AudioOut(self.audio_device, prepared.sr)
            out.write(prepared.audio)
            out.finish()
            out.open()  # outside the control tick that starts it
            self._owner.post(lambda: self._play(h, prepared.trajectory, out))
        except Exception as e:  # reported on the handle; the session goes on
            self._owner.post(lambda: self._preparing.discard(h))
            if not h.done:
                h._fail(e)
            self._idle_resume()

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
        self.check_open()
        body = body_language(style, amount, gestures, what="stream")
        assert self.planning is not None
        gen = self.planning.stream_generator(body)
        return StreamUtterance(
            self, self.planning, int(sample_rate), self.lookahead_s if lookahead_s is None else lookahead_s, gen
        )

    def _play(self, h: UtteranceHandle, traj: Trajectory, out: AudioOut) -> None:
        """In the owner: hand ``traj`` to the loop, its audio to start with it; not if :meth:`interrupt` abandoned
        it since it was asked for (the idle motion then comes back)."""
        if h not in self._preparing:
            out.stop()
            h._abandon("interrupt")
            self._idle_resume()
            return
        self._preparing.discard(h)

        def on_start() -> None:  # in the loop's tick: keep short
            play.on_start = None  # called once: the handle kept after the utterance must not keep its audio
            h._add("audio_start", played=out.start())

        try:
            play = self.check_open().play(traj, approach_within_rad=self.approach_within_rad)
        except Exception as e:  # the session died or closed meanwhile
            out.stop()
            h._fail(e)
            return
        play.on_start = on_start
        self._replace_audio(out)
        self._current = h
        h._attach(play)

    def _replace_audio(self, out: AudioOut | None) -> None:
        """In the owner: the speech audio playing stops (unless it is ``out``); ``out`` (None: nothing) becomes the
        session's."""
        if self._audio is not None and self._audio is not out:
            self._audio.stop()
        self._audio = out

    def _cancel(self) -> None:
        """In the owner: utterances asked for so far are not started (:meth:`_play`), the audio stops, and every
        unfinished stream is interrupted."""
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
        loop = self.check_open()
        t0 = time.monotonic()

        # One message: the idle motion cannot be switched on between the cancel and the glide's start.
        def cancel_and_glide() -> PlayHandle:
            self._cancel()
            return loop.interrupt()

        rest = self._owner.call(cancel_and_glide)

        def resume() -> None:
            try:
                rest.wait()
            except RuntimeError:  # the session closed meanwhile: its own glide took the robot to rest
                return
            idle = self.idle
            if idle is not None:
                self._owner.call(lambda: idle.after_glide(rest))

        if not wait:
            threading.Thread(target=resume, daemon=True, name="robogest-resume-idle").start()
            return {"interrupt_s": t0, "at_rest_s": None}
        resume()
        return {"interrupt_s": t0, "at_rest_s": rest.events["done"].monotonic_s if "done" in rest.events else None}

    # --- what a stream tells the session (run in the owner, in order with everything else) ---------------------
    def _stream_opened(self, st: StreamUtterance, opened: bool = True) -> None:
        self._owner.post(lambda: self._streams.add(st) if opened else self._streams.discard(st))

    def _stream_playing(self, st: StreamUtterance, out: AudioOut) -> None:
        """Its first frames play: it replaces the utterance playing (whose audio stops now), unless interrupted."""

        def message() -> None:
            if st.dead:  # interrupted since its play began
                out.stop()
                return
            self._replace_audio(out)
            self._current = st.handle

        self._owner.post(message)

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


__all__ = ["EVENT_TYPES", "Robot", "StreamUtterance", "UtteranceHandle"]
