"""A streamed utterance of a live session (:meth:`Robot.stream <robogest.live.Robot.stream>`): speech chunks from a
voice agent, planned in the stream's own thread by :class:`~robogest.live.planner.StreamingPlanner` while they play.
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from robogest.errors import InputError
from robogest.live.utterance import UtteranceHandle
from robogest.media.audio import AudioOut

if TYPE_CHECKING:
    from robogest.live.planning import Planning
    from robogest.live.session import Robot
    from robogest.trajectory import Trajectory


class StreamUtterance:
    """A streamed utterance (see :meth:`Robot.stream`); a context manager that closes the stream on exit.

    ``feed(chunk, words=None)``: mono int16/float32 PCM at ``sample_rate`` (10-100 ms per chunk), with optional
    word timings ``(text, start_s, end_s)`` in seconds from the utterance start. ``feed`` only checks and queues
    the chunk: the front-end and the planner run in the stream's own thread, so a voice agent's audio loop is never
    held up by planning. On leaving the block the stream is closed and the motion finishes; an exception inside
    the block interrupts the robot (glide to rest) instead. A failure in the planning thread interrupts the robot
    too, and is raised by the next ``feed``, ``close`` or ``wait``.
    """

    def __init__(self, robot: Robot, planning: Planning, sample_rate: int, lookahead_s: float, generator: Any) -> None:
        from robogest.live.planner import StreamingPlanner
        from robogest.speech.stream import SpeechStream, pcm_to_float

        self.robot = robot
        self.sample_rate = sample_rate
        self._pcm = pcm_to_float
        self.speech = SpeechStream(sample_rate, lookahead_s=lookahead_s)
        self._planning = planning
        self.planner = StreamingPlanner(robot.config, generator, planning.ik, self.speech, seed=robot.seed)
        self.handle = UtteranceHandle("stream")
        self.handle.trajectory = self.planner.feed
        self._out = AudioOut(robot.audio_device, sample_rate)
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
        robot._stream_opened(self)  # the utterance playing keeps its audio until this one has motion (_start)
        self._thread.start()

    def __enter__(self) -> StreamUtterance:
        return self

    def __exit__(self, et: type[BaseException] | None, *exc: object) -> None:
        if et is not None and not self._dead and self.robot.loop is not None and not self.robot.loop.closed:
            with contextlib.suppress(Exception):
                self.robot.interrupt(wait=issubclass(et, Exception))
            return
        self.close()

    @property
    def dead(self) -> bool:
        """Interrupted, or stopped by a failure: nothing more of it plays."""
        return self._dead

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
            self.robot._stream_opened(self, False)  # planned to the end (or stopped): interrupt() stops its motion

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
            play = self.handle.play_handle
            if playing and play is not None and not play.done:  # still what the robot plays: stop it
                with contextlib.suppress(Exception):
                    self.robot.interrupt(wait=False)
            elif not playing:  # (a stream another utterance has replaced leaves that one alone)
                self.robot._idle_resume()

    def _plan(self) -> int:
        with self._planning.plan_lock:  # the planners share the session's IK solver
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
            start_at, loop = None, r.loop
            assert loop is not None  # (a stream exists only while its session is open)
            if loop.wall_clock and self._t_first is not None:
                start_at = max(loop.now_s, loop.loop_s_at(self._t_first + self.speech.lookahead_s))
            feed = cast("Trajectory", self.planner.feed)  # plays like one (ControlLoop.play samples it, growing)
            try:
                play = loop.play(feed, start_at=start_at, approach_within_rad=r.approach_within_rad)
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
        r._stream_playing(self, out)  # this utterance replaces the one playing: its audio stops now

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
