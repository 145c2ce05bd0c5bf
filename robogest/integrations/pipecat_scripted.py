"""Offline stand-ins for a Pipecat pipeline's TTS service and output transport: no network, no cloud keys.

:class:`ScriptedTTS` speaks each ``TTSSpeakFrame`` with eSpeak NG (:func:`robogest.synthesize`) and emits what a
streaming TTS service with word timestamps emits, in real time: ``TTSStartedFrame``, 20 ms ``TTSAudioRawFrame`` s
(16-bit mono PCM), a word-timestamp ``TTSTextFrame`` as each word starts, ``TTSStoppedFrame``; an
``InterruptionFrame`` cuts it short. :class:`OutputRecorder` stands in for ``transport.output()``: it keeps the
frames that reach it and sends ``BotStartedSpeakingFrame`` / ``BotStoppedSpeakingFrame`` upstream as a transport
does. Used by ``examples/pipecat_local.py``, the tests and ``benchmarks/bench_pipecat.py``.
"""

from __future__ import annotations

import asyncio
import time
from typing import TYPE_CHECKING, Any

from robogest.integrations.pipecat import FrameDirection, FrameProcessor  # first: refuses a missing extra

# isort: split
from pipecat.frames.frames import (
    BotStartedSpeakingFrame,
    BotStoppedSpeakingFrame,
    Frame,
    InterruptionFrame,
    TTSAudioRawFrame,
    TTSSpeakFrame,
    TTSStartedFrame,
    TTSStoppedFrame,
    TTSTextFrame,
)

if TYPE_CHECKING:
    from robogest.live import Robot
    from robogest.speech.types import Speech


class ScriptedTTS(FrameProcessor):
    """A TTS service stand-in: each ``TTSSpeakFrame`` is spoken (eSpeak NG), in ``chunk_s`` audio frames sent
    ``speed`` times faster than real time (1.0: as a live TTS stream arrives at worst).

    ``sent``: every frame it emitted downstream, in order (what a test compares with what came out).
    """

    def __init__(self, *, chunk_s: float = 0.02, speed: float = 1.0, voice: str = "en-us", **kwargs: Any):
        super().__init__(**kwargs)
        self.chunk_s, self.speed, self.voice = float(chunk_s), float(speed), voice
        self.sent: list[Frame] = []
        self._speaking: asyncio.Task | None = None
        self._cache: dict[str, Speech] = {}

    async def process_frame(self, frame: Frame, direction: FrameDirection) -> None:
        await super().process_frame(frame, direction)
        if isinstance(frame, TTSSpeakFrame):
            await self._stop()
            self._speaking = self.create_task(self._speak(frame.text), name="scripted-tts")
            return  # a TTS service consumes the text it speaks
        if isinstance(frame, InterruptionFrame):
            await self._stop()
        await self.push_frame(frame, direction)

    async def _stop(self) -> None:
        if self._speaking is not None and not self._speaking.done():
            await self.cancel_task(self._speaking)
        self._speaking = None

    async def speech(self, text: str) -> Speech:
        """The :class:`~robogest.speech.Speech` of ``text`` (synthesised off the event loop, then cached)."""
        if text not in self._cache:
            from robogest.speech import synthesize

            self._cache[text] = await asyncio.to_thread(synthesize, text, self.voice)
        return self._cache[text]

    async def _emit(self, frame: Frame) -> None:
        self.sent.append(frame)
        await self.push_frame(frame)

    async def _speak(self, text: str) -> None:
        import numpy as np

        sp = await self.speech(text)
        pcm = np.round(np.clip(sp.audio, -1.0, 1.0) * 32767).astype("<i2")
        step = max(1, round(self.chunk_s * sp.sr))
        words = list(sp.words)
        await self._emit(TTSStartedFrame())
        t0, t0_ns = time.monotonic(), self.get_clock().get_time()
        for k, i in enumerate(range(0, len(pcm), step)):
            await self._emit(TTSAudioRawFrame(pcm[i : i + step].tobytes(), sp.sr, 1))
            while words and words[0].start_s < (i + step) / sp.sr:  # words starting in this chunk
                w = words.pop(0)
                word = TTSTextFrame(w.text, text_type="word")
                word.pts = t0_ns + round(w.start_s * 1e9)
                await self._emit(word)
            await asyncio.sleep(max(0.0, t0 + (k + 1) * self.chunk_s / self.speed - time.monotonic()))
        await self._emit(TTSStoppedFrame())


class OutputRecorder(FrameProcessor):
    """A ``transport.output()`` stand-in: records every frame that reaches it (``frames``) and, like a transport,
    sends ``BotStartedSpeakingFrame`` upstream on the first audio and ``BotStoppedSpeakingFrame`` when the TTS
    stops or is interrupted."""

    def __init__(self, **kwargs: Any):
        super().__init__(**kwargs)
        self.frames: list[Frame] = []
        self.speaking = False

    async def process_frame(self, frame: Frame, direction: FrameDirection) -> None:
        await super().process_frame(frame, direction)
        if direction is FrameDirection.DOWNSTREAM:
            self.frames.append(frame)
        if isinstance(frame, TTSAudioRawFrame) and not self.speaking:
            self.speaking = True
            await self.push_frame(BotStartedSpeakingFrame(), FrameDirection.UPSTREAM)
        elif isinstance(frame, (TTSStoppedFrame, InterruptionFrame)) and self.speaking:
            self.speaking = False
            await self.push_frame(BotStoppedSpeakingFrame(), FrameDirection.UPSTREAM)
        await self.push_frame(frame, direction)


class LocalPipeline:
    """``ScriptedTTS -> RobotGestureProcessor(robot) -> OutputRecorder`` run by Pipecat's own ``PipelineWorker``
    and ``WorkerRunner``, as an async context manager (the pipeline ends with an ``EndFrame`` on exit)::

        async with LocalPipeline(robot) as p:
            await p.say("Hello there!")  # returns when the TTS has sent the last audio frame
    """

    def __init__(self, robot: Robot, *, speed: float = 1.0, **processor_options: Any):
        from robogest.integrations.pipecat import RobotGestureProcessor

        self.tts = ScriptedTTS(speed=speed)
        self.gestures = RobotGestureProcessor(robot, **processor_options)
        self.output = OutputRecorder()
        self._run: asyncio.Task | None = None

    async def __aenter__(self) -> LocalPipeline:
        from pipecat.pipeline.pipeline import Pipeline
        from pipecat.pipeline.worker import PipelineWorker
        from pipecat.workers.runner import WorkerRunner

        pipeline = Pipeline([self.tts, self.gestures, self.output])
        self.worker = PipelineWorker(pipeline, idle_timeout_secs=None, enable_rtvi=False)
        runner = WorkerRunner(handle_sigint=False)
        await runner.add_workers(self.worker)
        self._run = asyncio.create_task(runner.run())
        return self

    async def __aexit__(self, et: type[BaseException] | None, *exc: object) -> None:
        from pipecat.frames.frames import EndFrame

        assert self._run is not None
        if et is None:
            await self.worker.queue_frame(EndFrame())
        else:
            await self.worker.cancel()
        await asyncio.wait_for(self._run, 30.0)

    async def speak(self, text: str) -> None:
        """Queue ``text`` for the TTS (returns at once)."""
        await self.tts.speech(text)  # synthesised before it is queued: the TTS starts streaming at once
        await self.worker.queue_frame(TTSSpeakFrame(text))

    async def say(self, text: str) -> None:
        """Speak ``text``; returns when its ``TTSStoppedFrame`` has left the pipeline."""
        n = sum(isinstance(f, TTSStoppedFrame) for f in self.output.frames)
        await self.speak(text)
        while sum(isinstance(f, TTSStoppedFrame) for f in self.output.frames) <= n:
            await asyncio.sleep(0.01)

    async def interrupt(self) -> None:
        """What a user barging in does: an ``InterruptionFrame`` through the pipeline."""
        await self.worker.queue_frame(InterruptionFrame())


__all__ = ["LocalPipeline", "OutputRecorder", "ScriptedTTS"]
