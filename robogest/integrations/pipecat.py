"""Pipecat adapter: a ``FrameProcessor`` that makes a :class:`~robogest.live.Robot` gesture to the bot's speech.

Place it right after the TTS service (``... llm, tts, RobotGestureProcessor(robot), transport.output()``)::

    from robogest.integrations.pipecat import RobotGestureProcessor

What it does with the frames it sees (every frame is passed on unchanged, in order, in its direction):

* the first non-silent ``TTSAudioRawFrame`` of a bot turn opens a :meth:`Robot.stream` at the frame's sample
  rate; that turn's audio frames are fed to it (multi-channel audio is mixed down for the robot only);
* word-timestamp ``TTSTextFrame`` s (``text_type == "word"``, with a ``pts``) become the stream's word timings:
  a word's start is its ``pts`` minus the clock time of the turn's first audio frame; its end is estimated from
  its length (the frames carry no end); each goes with the next audio frame;
* ``TTSStoppedFrame``, ``BotStoppedSpeakingFrame`` or ``EndFrame`` (whichever comes first) closes the turn's
  stream: the motion plays out and ends at rest;
* ``InterruptionFrame`` and ``CancelFrame`` call :meth:`Robot.interrupt` while a turn's motion is playing (the
  robot glides to rest; the idle motion resumes).

Robot calls run in one worker thread of this processor, in frame order: the pipeline's event loop only hands
them over (``ThreadPoolExecutor.submit``), so it never waits for planning, a lock or a servo. The stream's
motion plays ``robot.lookahead_s`` behind the first audio of the turn (see ``docs/voice-agents.md``).
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robogest.errors import InputError, MissingDependencyError

try:
    from pipecat.frames.frames import (
        BotStoppedSpeakingFrame,
        CancelFrame,
        EndFrame,
        Frame,
        InterruptionFrame,
        TTSAudioRawFrame,
        TTSStoppedFrame,
        TTSTextFrame,
    )
    from pipecat.processors.frame_processor import FrameDirection, FrameProcessor
except ImportError as exc:  # the extra is not installed
    from robogest.extras import install_command

    raise MissingDependencyError(
        f"the Pipecat integration needs Pipecat ({exc.name or 'pipecat'} is missing): {install_command('pipecat')}"
    ) from None

if TYPE_CHECKING:
    import numpy as np

    from robogest.live import Robot, UtteranceHandle
    from robogest.live.session import StreamUtterance

log = logging.getLogger("robogest.integrations.pipecat")


def _word_s(text: str) -> float:
    """A word's length, estimated (Pipecat's word frames carry only the start): 65 ms a letter, 0.15-0.6 s."""
    return min(0.6, max(0.15, 0.065 * sum(c.isalnum() for c in text)))


@dataclass
class Turn:
    """One bot turn as the processor saw it.

    ``first_audio_s``: ``time.monotonic()`` when its first audio frame reached the processor; ``stream``: its
    :class:`~robogest.live.session.StreamUtterance` (None until the worker thread opened it, or if that failed);
    ``n_frames``: audio frames of the turn handed to the robot.
    """

    first_audio_s: float
    sample_rate: int
    stream: StreamUtterance | None = None
    n_frames: int = 0

    @property
    def handle(self) -> UtteranceHandle | None:
        """The stream's :class:`~robogest.live.UtteranceHandle` (its events: ``first_goal``, ``done``...)."""
        return None if self.stream is None else self.stream.handle


class RobotGestureProcessor(FrameProcessor):
    """Streams a Pipecat bot's TTS audio (and word timings) into ``robot``; turns interruptions into
    :meth:`Robot.interrupt`. See the module docstring for the frames it acts on.

    Parameters
    ----------
    robot : Robot
        An open session (``robot.open()`` or ``with Robot(...) as robot``); the caller closes it.
    lookahead_s : float, optional
        L of each stream (default: the robot's ``lookahead_s``).
    keep_turns : int
        How many recent :class:`Turn` records :attr:`turns` keeps (for latency checks).
    **kwargs
        Passed to ``FrameProcessor`` (e.g. ``name``).
    """

    def __init__(self, robot: Robot, *, lookahead_s: float | None = None, keep_turns: int = 100, **kwargs: Any):
        super().__init__(**kwargs)
        self.robot = robot
        self.lookahead_s = lookahead_s
        self.turns: deque[Turn] = deque(maxlen=keep_turns)  #: recent turns, oldest first
        self.last_error: BaseException | None = None  #: the last failure of a robot call (logged, not raised)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="robogest-pipecat")
        self._gen = 0  # bumped by every interrupt: the worker drops what was queued for an older generation
        self._turn: Turn | None = None  # the open turn (event-loop side)
        self._t0_ns = 0  # pipeline clock at the turn's first audio frame (word pts are on that clock)
        self._words: list[tuple[str, float, float]] = []  # words for the next feed
        self._last_word_s = 0.0
        self._stream: StreamUtterance | None = None  # the open stream (worker side)
        self._stream_turn: Turn | None = None  # the turn it belongs to
        self._moving: UtteranceHandle | None = None  # the last stream's handle (worker side)

    # --- the event loop's side: classify, hand over, pass on ------------------------------------------
    async def process_frame(self, frame: Frame, direction: FrameDirection) -> None:
        await super().process_frame(frame, direction)
        if isinstance(frame, TTSAudioRawFrame):
            self._on_audio(frame)
        elif isinstance(frame, TTSTextFrame):
            self._on_text(frame)
        elif isinstance(frame, (TTSStoppedFrame, BotStoppedSpeakingFrame, EndFrame)):
            self._end_turn()
        elif isinstance(frame, (InterruptionFrame, CancelFrame)):
            self._interrupt()
        await self.push_frame(frame, direction)

    def _on_audio(self, frame: TTSAudioRawFrame) -> None:
        turn = self._turn
        if turn is None:
            if not frame.audio or frame.audio.count(0) == len(frame.audio):
                return  # silence between turns (e.g. after TTSStoppedFrame) starts no motion
            turn = self._turn = Turn(time.monotonic(), int(frame.sample_rate))
            self.turns.append(turn)
            self._t0_ns = self.get_clock().get_time()
            self._words, self._last_word_s = [], 0.0
            self._submit(self._w_open, turn)
        if frame.sample_rate != turn.sample_rate:
            log.warning("pipecat: audio at %d Hz in a turn that began at %d Hz: not fed to the robot",
                        frame.sample_rate, turn.sample_rate)  # fmt: skip
            return
        words, self._words = self._words, []
        turn.n_frames += 1
        self._submit(self._w_feed, turn, frame.audio, int(frame.num_channels), words)

    def _on_text(self, frame: TTSTextFrame) -> None:
        """A word with a timestamp goes with the next audio frame, at once: the planner expects a beat on its
        stressed syllable, and the earlier it knows the word, the more warning the robot has."""
        if self._turn is None or frame.pts is None or str(frame.text_type) != "word" or not frame.text.strip():
            return
        text = frame.text.strip()
        start_s = max(self._last_word_s, (frame.pts - self._t0_ns) / 1e9, 0.0)
        self._words.append((text, start_s, start_s + _word_s(text)))
        self._last_word_s = start_s

    def _end_turn(self) -> None:
        turn = self._turn
        if turn is None:
            return
        words, self._words, self._turn = self._words, [], None
        self._submit(self._w_close, turn, words)

    def _interrupt(self) -> None:
        self._gen += 1
        self._turn, self._words = None, []
        self._submit(self._w_interrupt)

    def _submit(self, fn: Callable[..., None], *args: object) -> None:
        # RuntimeError: the pool was shut down (the pipeline ended): nothing more goes to the robot.
        with contextlib.suppress(RuntimeError):
            self._pool.submit(self._guarded, fn, self._gen, *args)

    async def cleanup(self) -> None:
        """The pipeline is torn down: close the open stream (the motion plays out); the robot stays open."""
        self._end_turn()
        self._pool.shutdown(wait=False)
        await super().cleanup()

    # --- the worker thread's side: robot calls, in frame order ----------------------------------------
    def _guarded(self, fn: Callable[..., None], gen: int, *args: object) -> None:
        if gen != self._gen and fn is not self._w_interrupt:
            return  # queued before an interrupt: that turn is over
        try:
            fn(*args)
        except Exception as e:  # the voice agent keeps talking; the robot's part of the turn ends here
            st, self._stream = self._stream, None
            if st is not None:
                with contextlib.suppress(Exception):
                    st.close()  # what was planned plays out to rest
            if str(e) != str(self.last_error):
                log.warning("pipecat: robot call %s failed: %s", fn.__name__, e)
            self.last_error = e

    def _w_open(self, turn: Turn) -> None:
        if self._stream is not None:  # a turn that never closed (no stop frame came): its speech is complete
            self._stream.close()
        stream = self.robot.stream(turn.sample_rate, self.lookahead_s)
        self._stream, self._stream_turn = stream, turn
        turn.stream, self._moving = stream, stream.handle

    def _w_feed(self, turn: Turn, audio: bytes, channels: int, words: list) -> None:
        st = self._stream
        if st is None or self._stream_turn is not turn:
            return
        st.feed(_mono_int16(audio, channels), words=_usable(words) or None)

    def _w_close(self, turn: Turn, words: list) -> None:
        st = self._stream
        if st is None or self._stream_turn is not turn:
            return
        self._stream = None
        if words := _usable(words):
            st.feed(b"", words=words)
        st.close()

    def _w_interrupt(self) -> None:
        self._stream = None
        moving = self._moving
        if moving is not None and not moving.done:
            self.robot.interrupt(wait=False)


def _usable(words: list[tuple[str, float, float]]) -> list[tuple[str, float, float]]:
    """The words the robot's stream takes (a token with no letters or digits, e.g. a dash, is left out)."""
    from robogest.speech.stream import parse_word

    out = []
    for w in words:
        with contextlib.suppress(InputError):
            parse_word(w)
            out.append(w)
    return out


def _mono_int16(audio: bytes, channels: int) -> bytes | np.ndarray:
    """Pipecat's PCM (16-bit, interleaved) as the robot takes it: bytes when mono, else the channels' mean."""
    if channels <= 1:
        return audio
    import numpy as np

    a = np.frombuffer(audio, "<i2")
    a = a[: a.size - a.size % channels].reshape(-1, channels)
    mono: np.ndarray = a.mean(axis=1).astype(np.int16)  # (N,)
    return mono


__all__ = ["RobotGestureProcessor", "Turn"]
