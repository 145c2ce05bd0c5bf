"""One client of ``robogest serve`` (:mod:`robogest.live.server`): its messages dispatched to the robot's session,
its stream fed within the buffer limit, and its utterances' events pushed back as they happen."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import time
from collections.abc import Coroutine
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from robogest.errors import InputError, RobogestError
from robogest.live.serve_limits import release_freed_memory
from robogest.live.serve_messages import check_id, message_body, parse_message, plain_event

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection

    from robogest.live.server import Server
    from robogest.live.session import Robot
    from robogest.live.stream import StreamUtterance
    from robogest.live.utterance import UtteranceHandle

log = logging.getLogger("robogest.live.server")  # one log for the whole server (module docstring there)

EVENT_POLL_S = 0.02  #: how often an utterance's events and preparation are polled


_say_seq = itertools.count()


@dataclass
class Say:
    """A say waiting its client's turn in the server's round-robin queue."""

    conn: Connection
    obj: dict
    asked: int  #: the server's interrupt count when it came
    seq: int = field(default_factory=lambda: next(_say_seq))  #: order of arrival


def peer_of(conn: Any) -> str:
    """``host:port`` of a websockets connection, for the log."""
    addr = getattr(conn, "remote_address", None)
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)


class Connection:
    """One connected client: its messages (``_on_<type>``), its open stream and the tasks pushing its events."""

    def __init__(self, server: Server, ws: ServerConnection, peer: str = "?") -> None:
        self.server = server
        self.ws = ws
        self.peer = peer
        self.stream: StreamUtterance | None = None
        self.stream_format = "int16"
        self._fed_n = 0  #: samples fed to the open stream
        self._played_t0: float | None = None  #: time.monotonic() its audio started playing
        self._dropped = 0  #: its chunks refused for the buffer limit
        self.tasks: set[asyncio.Task] = set()

    @property
    def robot(self) -> Robot:
        return self.server.robot  # a reopened session replaces it

    async def send(self, obj: dict) -> None:
        with contextlib.suppress(Exception):  # the client may be gone; the robot carries on
            await self.ws.send(json.dumps(obj))

    async def error(self, message: str) -> None:
        log.warning("%s: %s", self.peer, message)
        await self.send({"type": "error", "message": message})

    def finish(self) -> None:
        for t in self.tasks:
            t.cancel()
        if self.stream is not None:  # a client that vanished mid-stream: finish what it said
            with contextlib.suppress(Exception):
                self.stream.close()
            self.stream = None

    async def dispatch(self, msg: str | bytes) -> None:
        try:
            if isinstance(msg, bytes):
                await self._pcm(msg)
                return
            obj = parse_message(msg)
            handler = getattr(self, "_on_" + obj["type"], None)
            if handler is None:
                raise InputError(
                    f"unknown message type {obj['type']!r}; one of say, stream_start, words, stream_end, interrupt, "
                    "status"
                )
            await handler(obj)
        except RobogestError as e:
            await self.error(str(e))
        except Exception as e:  # a bug must not end the session: report it, keep serving
            log.exception("%s: internal error", self.peer)
            await self.error(f"internal error: {type(e).__name__}: {e}")

    # --- messages -------------------------------------------------------------------------------------
    async def _on_status(self, obj: dict) -> None:
        await self.send({"type": "status", **self.server.status()})

    async def _on_interrupt(self, obj: dict) -> None:
        self.server.interrupts += 1  # says still waiting their turn are dropped
        res = await asyncio.to_thread(self.robot.interrupt)
        self._close_stream_state()
        t0, t1 = res.get("interrupt_s"), res.get("at_rest_s")
        log.info("%s: interrupt; at rest %s", self.peer, "(not reached)" if t1 is None else f"{t1 - t0:.2f} s after it")
        await self.send({"type": "interrupted", **res})

    async def _on_say(self, obj: dict) -> None:
        text, audio, transcript = obj.get("text"), obj.get("audio"), obj.get("transcript")
        for key, v in (("text", text), ("audio", audio), ("transcript", transcript)):
            if v is not None and not isinstance(v, str):
                raise InputError(f'say: "{key}" must be a string')
        limit = self.server.limits.max_say_chars
        if text is not None and len(text) > limit:
            raise InputError(
                f"say: text of {len(text)} characters is over the limit of {limit} (--max-say-chars); split it into "
                "several says"
            )
        if not isinstance(obj.get("lenient", False), bool):
            raise InputError('say: "lenient" must be true or false')
        check_id(obj)
        message_body(obj, "say")
        self.server.check_alive("say")
        self.server.enqueue(Say(self, obj, self.server.interrupts))

    async def start_say(self, say: Say) -> UtteranceHandle | None:
        """The say's turn: prepare it and start it playing; its handle (None: dropped or refused, client told)."""
        obj = say.obj
        if self.server.interrupts != say.asked:
            await self.error("say: dropped, an interrupt came before it started")
            return None
        if self.server.lost is not None:
            await self.error(f"say: refused, the robot session was lost ({self.server.lost})")
            return None
        try:  # say() only queues it; it is accepted once prepared (a bad file or tag: an error, not accepted)
            h = self.robot.say(
                obj.get("text"), audio=obj.get("audio"), transcript=obj.get("transcript"), wait=False,
                lenient=obj.get("lenient", False), **message_body(obj, "say"),
            )  # fmt: skip
            while not h.prepared:  # polled: the event loop never blocks on it
                await asyncio.sleep(EVENT_POLL_S / 4)
            h.wait_started(0)  # raises what went wrong while preparing
        except RobogestError as e:
            await self.error(f"say: {e}")
            return None
        log.info("%s: say accepted as utterance %d", self.peer, h.id)
        await self.send({"type": "accepted", "utterance": h.id, "id": obj.get("id")})
        self.spawn(self._pump(h))
        return h

    async def _on_stream_start(self, obj: dict) -> None:
        sr, fmt = obj.get("sample_rate", 16000), obj.get("format", "int16")
        if not isinstance(sr, int) or isinstance(sr, bool):
            raise InputError('stream_start: "sample_rate" must be an integer, Hz')
        if fmt not in ("int16", "float32"):
            raise InputError(f'stream_start: "format" {fmt!r} is not supported; use "int16" or "float32"')
        check_id(obj)
        body = message_body(obj, "stream_start")
        self.server.check_alive("stream_start")
        if self.stream is not None:
            await asyncio.to_thread(self.stream.close)
        self.stream = await asyncio.to_thread(self.robot.stream, sr, **body)
        self.stream_format = fmt
        self._fed_n, self._played_t0, self._dropped = 0, None, 0
        h = self.stream.handle
        log.info("%s: stream accepted as utterance %d (%d Hz %s)", self.peer, h.id, sr, fmt)
        await self.send({"type": "accepted", "utterance": h.id, "id": obj.get("id")})
        self.spawn(self._pump(h))

    def _buffered_s(self, st: StreamUtterance, more_n: int) -> float:
        """Seconds of the open stream ``st``'s audio ahead of what has played, with ``more_n`` samples more."""
        if self._played_t0 is None:
            ev = st.handle.event("audio_start")
            self._played_t0 = None if ev is None else ev["t_monotonic_s"]
        played_s = 0.0 if self._played_t0 is None else (time.monotonic() - self._played_t0) * self.robot.time_scale
        return (self._fed_n + more_n) / st.sample_rate - played_s

    async def _pcm(self, data: bytes) -> None:
        if self.stream is None:
            raise InputError('binary PCM without an open stream; send {"type": "stream_start"} first')
        from robogest.speech.stream import pcm_to_float

        width = 2 if self.stream_format == "int16" else 4
        if len(data) % width:
            raise InputError(f"PCM frame of {len(data)} bytes is not a whole number of {self.stream_format} samples")
        limit = self.server.limits.stream_buffer_s
        ahead = self._buffered_s(self.stream, len(data) // width)
        if ahead > limit:
            msg = (
                f"stream: this chunk would put {ahead:.1f} s of audio ahead of playback, over the {limit:g} s limit "
                "(--stream-buffer-s); it was dropped: feed the stream no faster than it plays"
            )
            self._dropped += 1  # every chunk is answered; the log says it once a stream (a flood is many a second)
            log.log(logging.WARNING if self._dropped == 1 else logging.DEBUG, "%s: %s", self.peer, msg)
            await self.send({"type": "error", "message": msg})
            return
        chunk = pcm_to_float(data, self.stream_format)
        await asyncio.to_thread(self.stream.feed, chunk)
        self._fed_n += chunk.shape[0]

    async def _on_words(self, obj: dict) -> None:
        if self.stream is None:
            raise InputError('words without an open stream; send {"type": "stream_start"} first')
        words = obj.get("words")
        if not isinstance(words, list):
            raise InputError('words: "words" must be a list of [text, start_s, end_s]')
        stream = self.stream
        await asyncio.to_thread(stream.feed, b"", [tuple(w) if isinstance(w, list) else w for w in words])

    async def _on_stream_end(self, obj: dict) -> None:
        if self.stream is None:
            raise InputError("stream_end without an open stream")
        stream, fed_s = self.stream, self._fed_n / self.stream.sample_rate
        self._close_stream_state()
        log.info("%s: stream utterance %d ended (%.1f s of audio)", self.peer, stream.handle.id, fed_s)
        await asyncio.to_thread(stream.close)

    def _close_stream_state(self) -> None:
        self.stream, self._fed_n, self._played_t0 = None, 0, None

    # --- events ---------------------------------------------------------------------------------------
    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        t = asyncio.ensure_future(coro)
        self.tasks.add(t)
        t.add_done_callback(self.tasks.discard)

    async def _pump(self, h: UtteranceHandle) -> None:
        """Push the utterance's events as they happen, until it is done."""
        seen: set[tuple] = set()
        while True:
            done = h.done
            for e in h.events:
                key = (e["type"], e["t_monotonic_s"], e.get("offset_s"))
                if key not in seen:
                    seen.add(key)
                    await self.send({"type": "event", "utterance": h.id, "event": e["type"], **plain_event(e)})
            if done:
                log.info("%s: utterance %d %s", self.peer, h.id, "interrupted" if h.interrupted else "done")
                await asyncio.to_thread(release_freed_memory)
                return
            await asyncio.sleep(EVENT_POLL_S)
