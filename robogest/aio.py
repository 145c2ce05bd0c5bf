"""The live session for asyncio programs (voice agents): every call returns without blocking the event loop.

::

    from robogest.aio import AsyncRobot

    async with AsyncRobot("humanoid_xl430", backend="sim") as robot:  # open, then wait until ready
        await robot.say("Hello! Nice to meet you.")                    # until done
        h = await robot.say("Let me think.", wait=False, style="calm")  # at once
        await robot.interrupt()                                          # until at rest
        async with robot.stream(16000) as s:                             # speech from a TTS, chunk by chunk
            await s.feed(chunk)
        await s.wait()

:class:`AsyncRobot` wraps a :class:`~robogest.live.Robot`: ``say`` only queues the utterance (it is prepared in the
session's worker thread), waiting is polling with ``asyncio.sleep``, and the calls that block (open, close,
interrupt, starting a stream) run in a thread with ``asyncio.to_thread``. The blocking API stays as it is.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Generator, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robogest.live import Robot, StreamUtterance, UtteranceHandle

#: How often an awaited utterance is checked, seconds (events arrive on the robot's own threads).
POLL_S = 0.01


class AsyncUtterance:
    """An utterance of an :class:`AsyncRobot`: ``await`` it to wait until done (raises its failure)."""

    def __init__(self, handle: UtteranceHandle) -> None:
        self.handle = handle  #: the :class:`~robogest.live.UtteranceHandle`

    @property
    def id(self) -> int:
        return self.handle.id

    @property
    def done(self) -> bool:
        return self.handle.done

    @property
    def interrupted(self) -> bool:
        return self.handle.interrupted

    @property
    def events(self) -> list[dict]:
        return self.handle.events

    def event(self, type_: str) -> dict | None:
        return self.handle.event(type_)

    async def wait(self, timeout_s: float | None = None) -> bool:
        """Until done (True) or ``timeout_s`` (False); raises a failure of its preparation or of the robot."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.handle.done:
            if deadline is not None and time.monotonic() >= deadline:
                return False
            await asyncio.sleep(POLL_S)
        return self.handle.wait(0)  # raises what the handle holds; returns at once

    def __await__(self) -> Generator[Any, None, bool]:
        return self.wait().__await__()


class AsyncStream:
    """A streamed utterance of an :class:`AsyncRobot` (``async with robot.stream(16000) as s``).

    On leaving the block the stream is closed and its motion plays out; an exception inside it interrupts the
    robot instead (as :class:`~robogest.live.StreamUtterance`)."""

    def __init__(self, robot: AsyncRobot, kwargs: dict) -> None:
        self._robot = robot
        self._kwargs = kwargs
        self.stream: StreamUtterance | None = None  #: the :class:`~robogest.live.StreamUtterance`, once started

    async def start(self) -> AsyncStream:
        robot = self._robot.session
        self.stream = await asyncio.to_thread(lambda: robot.stream(**self._kwargs))
        return self

    @property
    def _st(self) -> StreamUtterance:
        if self.stream is None:
            from robogest.errors import InputError

            raise InputError("stream: not started; use `async with robot.stream(...) as s` (or await it) first")
        return self.stream

    def __await__(self) -> Generator[Any, None, AsyncStream]:
        return self.start().__await__()

    async def __aenter__(self) -> AsyncStream:
        return await self.start()

    async def __aexit__(self, et: type[BaseException] | None, *exc: object) -> None:
        st = self._st
        if et is not None:
            await asyncio.to_thread(st.__exit__, et, *exc)
            return
        st.close()  # queues the end: returns at once

    @property
    def handle(self) -> AsyncUtterance:
        return AsyncUtterance(self._st.handle)

    async def feed(self, chunk: Any, words: Sequence[tuple[str, float, float]] | None = None) -> None:
        """Add a chunk of PCM (and word timings); checks and queues it (the planning runs in the stream's thread)."""
        self._st.feed(chunk, words)

    async def close(self) -> AsyncUtterance:
        self._st.close()
        return self.handle

    async def wait(self, timeout_s: float | None = None) -> bool:
        """Until the streamed utterance is done; raises a failure of its planning thread."""
        done = await self.handle.wait(timeout_s)
        self._st.wait(0)
        return done


class AsyncRobot:
    """A :class:`~robogest.live.Robot` for asyncio: the same arguments, or ``robot=`` an existing one.

    ``async with AsyncRobot(...)`` opens the session and waits until it is :attr:`ready`; leaving the block closes
    it (glide to rest, torque off), also on an exception or cancellation.
    """

    def __init__(self, *args: Any, robot: Any = None, **kwargs: Any) -> None:
        if robot is not None and (args or kwargs):
            from robogest.errors import InputError

            raise InputError("AsyncRobot: give robot=Robot(...) or the Robot's arguments, not both")
        self._args, self._kwargs = args, kwargs
        self.robot: Robot | None = (
            robot  #: the wrapped :class:`~robogest.live.Robot` (made by :meth:`open` if not given)
        )

    # --- life cycle ----------------------------------------------------------------------------------
    async def open(self) -> AsyncRobot:
        """Connect and start the session (in a thread); does not wait for :attr:`ready`."""
        if self.robot is None:
            from robogest.live import Robot

            self.robot = await asyncio.to_thread(Robot, *self._args, **self._kwargs)
        await asyncio.to_thread(self.robot.open)
        return self

    @property
    def session(self) -> Robot:
        """The wrapped :class:`~robogest.live.Robot`; InputError before :meth:`open` made it."""
        if self.robot is None:
            from robogest.errors import InputError

            raise InputError("robot session is not open (never opened); use `async with AsyncRobot(...) as robot:`")
        return self.robot

    async def close(self) -> str | None:
        """Stop, glide to rest, torque off (in a thread); returns why rest was not reached, or None."""
        if self.robot is None:
            return None
        return await asyncio.to_thread(self.robot.close)

    async def __aenter__(self) -> AsyncRobot:
        await self.open()
        try:
            await self.wait_ready()
        except BaseException:
            await asyncio.shield(self.close())
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        await asyncio.shield(self.close())  # a cancelled task still ends at rest

    @property
    def ready(self) -> bool:
        return self.robot is not None and self.robot.ready

    async def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Until the session is ready (True) or ``timeout_s`` (False)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        robot = self.session
        robot.check_open()
        while not robot.ready:
            robot.check_open()
            if deadline is not None and time.monotonic() >= deadline:
                return False
            await asyncio.sleep(POLL_S)
        return True

    # --- utterances ----------------------------------------------------------------------------------
    async def say(self, text: str | None = None, *, wait: bool = True, **kwargs: Any) -> AsyncUtterance:
        """:meth:`Robot.say <robogest.live.Robot.say>` (same arguments): queued at once; awaited until done when
        ``wait``. A bad argument raises here; a failure while preparing is raised when the utterance is awaited."""
        h = AsyncUtterance(self.session.say(text, wait=False, **kwargs))
        if wait:
            await h
        return h

    def stream(self, sample_rate: int = 16000, lookahead_s: float | None = None, **kwargs: Any) -> AsyncStream:
        """``async with robot.stream(16000, style="lively") as s: await s.feed(chunk)``; or ``await`` it."""
        return AsyncStream(self, {"sample_rate": sample_rate, "lookahead_s": lookahead_s, **kwargs})

    async def interrupt(self, wait: bool = True) -> dict:
        """Stop speaking and glide to rest; with ``wait``, returns once at rest (see :meth:`Robot.interrupt`)."""
        return await asyncio.to_thread(self.session.interrupt, wait)

    def status(self) -> dict:
        return self.session.status()


__all__ = ["AsyncRobot", "AsyncStream", "AsyncUtterance"]
