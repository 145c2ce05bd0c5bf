"""``robogest serve``: one :class:`~robogest.live.Robot` session behind a local WebSocket server.

Protocol (version 1). Text frames are JSON objects with a ``type``; binary frames are PCM of the open stream.

Client -> server:

* ``{"type": "say", "text": "..."}`` or ``{"type": "say", "audio": "/path.wav", "transcript": "/path.TextGrid"}``
  (files on the server's machine); optional ``"id"`` (a string or an integer) is echoed back, optional
  ``"lenient": true`` drops the text's tags that robogest cannot use (docs/animated-speech.md); optional body
  language for this utterance only: ``"style"`` (calm, neutral, lively) or ``"amount"`` (0-2), and ``"gestures"``
  ("auto", "none", or a folder or YAML file of gesture units on the server's machine);
* ``{"type": "stream_start", "sample_rate": 16000, "format": "int16"}`` (or ``"float32"``; and the same optional
  ``"style"``, ``"amount"``, ``"gestures"``), then binary frames of
  mono little-endian PCM (10-100 ms each), optional ``{"type": "words", "words": [["hello", 0.0, 0.31], ...]}``
  (seconds from the stream's start), then ``{"type": "stream_end"}``;
* ``{"type": "interrupt"}``: stop now, glide to rest;
* ``{"type": "status"}``.

Server -> client: ``{"type": "hello", "protocol": 1, ...status}`` on connect; ``{"type": "accepted", "utterance": N,
"id": ...}`` for each say/stream; ``{"type": "event", "utterance": N, "event": "first_goal", "t_monotonic_s": ...}``
for every utterance event (``audio_chunk`` events carry ``offset_s`` and the play time when the server cannot play
audio itself); ``{"type": "interrupted", "interrupt_s": ..., "at_rest_s": ...}``; ``{"type": "status", ...}``;
``{"type": "error", "message": "..."}`` for anything malformed or refused (the session keeps running);
``{"type": "session_lost", "message": ...}`` to every client when the robot's session dies (a servo lost: the robot
went to rest, torque off), then ``{"type": "session_restored", ...status}`` if reopening it once worked; otherwise
the server closes every connection and the process exits 5.

Says are queued per client and the queues served in turn (round-robin), each say played to its end before the next
is prepared, so one client's long say delays another's by at most the one playing. Streams start at once (they
replace what plays). Limits (:class:`ServeLimits`): clients connected, bytes per message, characters per say, and
seconds of audio a stream may hold ahead of playback.

Security: it listens on 127.0.0.1 by default; any other address than 127.0.0.1, ::1 or localhost needs a token
(``Authorization: Bearer T`` header or ``?token=T``). A WebSocket handshake with an ``Origin`` header (every browser
sends one) is refused unless that origin was allowed explicitly, so a web page cannot move the robot.

Logging (``robogest.live.server``): each connection (address, origin), each request (type, utterance), each refusal
and error, each interrupt with its timing, and the session's death.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import errno
import hmac
import itertools
import json
import logging
import os
import signal
import socket
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qs, urlsplit

from robogest.errors import BackendError, InputError, RobogestError

log = logging.getLogger(__name__)

PROTOCOL_VERSION = 1
_EVENT_POLL_S = 0.02
_WATCH_S = 0.05  #: how often the session's health is checked
#: Hosts that need no token: the loopback interface by its usual names (127.0.0.2 is loopback too, but an address
#: other than the default is a deliberate choice and gets the same rule as any other).
LOCAL_HOSTS = ("127.0.0.1", "::1", "localhost")


@dataclass(frozen=True)
class ServeLimits:
    """What one server accepts (CLI: ``--max-clients``, ``--max-say-chars``, ``--stream-buffer-s``).

    max_clients : clients connected at once; one more is answered with an ``error`` and closed.
    max_message_bytes : largest WebSocket message; a larger one closes that connection (code 1009).
    max_say_chars : longest ``say`` text (5000 characters, about 5 minutes of speech; its preparation takes a few
        seconds): a longer one is refused, so no say holds the robot's queue for minutes.
    stream_buffer_s : seconds of audio a stream may hold ahead of what has played; a chunk past it is refused (the
        stream goes on), so a client cannot pile up audio without bound.
    """

    max_clients: int = 8
    max_message_bytes: int = 1 << 20
    max_say_chars: int = 5000
    stream_buffer_s: float = 60.0


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> ``(host, port)``; InputError naming the fix."""
    host, sep, port = text.rpartition(":")
    try:
        if not sep or not host:
            raise ValueError
        p = int(port)
        if not 0 <= p <= 65535:
            raise ValueError
    except ValueError:
        raise InputError(f"--listen {text!r}: expected HOST:PORT, e.g. 127.0.0.1:8765") from None
    return host.strip("[]"), p


def needs_token(host: str) -> bool:
    """Every address but 127.0.0.1, ::1 and localhost needs a token."""
    return host not in LOCAL_HOSTS


def check_token(host: str, port: int, token: str | None) -> None:
    if needs_token(host) and not token:
        raise InputError(
            f"--listen {host}:{port}: only 127.0.0.1, ::1 and localhost are served without a token (anyone who "
            "reaches another address could move the robot); add --token SECRET (clients send "
            "'Authorization: Bearer SECRET')"
        )


def bind(host: str, port: int) -> socket.socket:
    """The listening socket, bound before the robot is opened: a busy address is one line and no torque."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, _, _, _, addr = min(infos, key=lambda i: i[0] != socket.AF_INET)  # localhost: 127.0.0.1 first
        return socket.create_server(addr[:2], family=family)
    except OSError as e:
        fix = (
            "another robogest serve may be using it: stop that one or choose another port"
            if e.errno == errno.EADDRINUSE
            else "give an address of this machine, e.g. 127.0.0.1:8765"
        )
        why = os.strerror(e.errno) if (e.errno or 0) > 0 else (e.strerror or str(e))  # gaierror: negative codes
        raise InputError(f"--listen {host}:{port}: cannot listen there ({why}); {fix}") from None


_say_seq = itertools.count()


@dataclass
class _Say:
    conn: _Connection
    obj: dict
    asked: int  #: the server's interrupt count when it came
    seq: int = field(default_factory=lambda: next(_say_seq))  #: order of arrival


class Server:
    """Serves ``robot`` (an open :class:`Robot`) on ``sock`` or ``host:port`` (see module docstring).

    ``reopen``: called once (in a worker thread) after the session died, returns a new open Robot; None, or a
    failure, ends :meth:`run` with a :class:`~robogest.errors.BackendError` (exit 5).
    """

    def __init__(
        self,
        robot: Any,
        host: str,
        port: int,
        *,
        token: str | None = None,
        allow_origins: Sequence[str] = (),
        limits: ServeLimits | None = None,
        sock: socket.socket | None = None,
        reopen: Callable[[], Any] | None = None,
    ) -> None:
        check_token(host, port, token)
        self.robot = robot
        self.host, self.port = host, port
        self.sock = sock
        self.token = token
        self.origins: list[str | None] = [None, *allow_origins]
        self.limits = limits or ServeLimits()
        self.reopen = reopen
        self.connections: set[_Connection] = set()
        #: Says waiting, per client (none empty), and the turn in which each client was last served (round-robin).
        self._queues: dict[_Connection, deque[_Say]] = {}
        self._served: dict[_Connection, int] = {}
        self._turn = itertools.count()
        self._wake = asyncio.Event()
        self._interrupts = 0  #: interrupts so far: a say that came before one is dropped, not started after it
        self.lost: str | None = None  #: why the robot's session died (None while it lives)
        self._stop: asyncio.Future | None = None

    # --- handshake ------------------------------------------------------------------------------------
    def _check_token(self, connection: Any, request: Any) -> Any:
        if not self.token:
            return None
        auth = request.headers.get("Authorization", "")
        scheme, _, value = auth.partition(" ")
        given = value.strip() if scheme.lower() == "bearer" else ""  # the scheme is case-insensitive (RFC 7235)
        if not given:
            given = (parse_qs(urlsplit(request.path).query).get("token") or [""])[0]
        if given and hmac.compare_digest(given.encode(), self.token.encode()):
            return None
        log.warning("refused %s: missing or wrong token", _peer(connection))
        return connection.respond(HTTPStatus.UNAUTHORIZED, "missing or wrong token\n")

    # --- session --------------------------------------------------------------------------------------
    async def run(self, ready: Any = None) -> None:
        """Serve until cancelled, SIGINT/SIGTERM/SIGHUP/SIGQUIT, or the session's death; ``ready(host, port)`` once
        listening.

        The event loop takes those signals itself (a Python signal handler would raise inside whichever task
        happens to run) and raises :class:`~robogest.backends.control.Interrupted` from here, so the session
        ends at rest and the process exits with 128 + the signal number. A session that died and could not be
        reopened raises :class:`~robogest.errors.BackendError` (exit 5), also when a signal comes meanwhile.
        """
        from websockets.asyncio.server import serve

        from robogest.backends.control import HANDLED_SIGNALS, deliver_signal

        loop = asyncio.get_running_loop()
        stop: asyncio.Future = loop.create_future()
        self._stop = stop
        taken: dict[int, Any] = {}
        for name in HANDLED_SIGNALS:
            sig = getattr(signal, name, None)
            prev = signal.getsignal(sig) if sig is not None else None
            if sig is None or (name == "SIGHUP" and prev == signal.SIG_IGN):
                continue
            try:
                loop.add_signal_handler(sig, lambda s=sig: stop.done() or stop.set_result(s))
            except (NotImplementedError, RuntimeError, ValueError):  # not the main thread, or no such support
                continue
            taken[sig] = prev
        where: dict[str, Any] = {"sock": self.sock} if self.sock is not None else {"host": self.host, "port": self.port}
        tasks: list[asyncio.Task] = []
        try:
            async with serve(
                self._handle, origins=self.origins, process_request=self._check_token,
                max_size=self.limits.max_message_bytes, **where,
            ) as server:  # fmt: skip
                sock = next(iter(server.sockets))
                self.port = sock.getsockname()[1]
                tasks = [asyncio.ensure_future(self._serve_says()), asyncio.ensure_future(self._watch())]
                if ready is not None:
                    ready(self.host, self.port)
                log.info("listening on ws://%s:%d", self.host, self.port)
                outcome = await stop
                if isinstance(outcome, BaseException) or self.lost is not None:
                    lost = f"robot session lost ({self.lost})"
                    failure = str(outcome) if isinstance(outcome, BaseException) else lost
                    for c in list(self.connections):
                        with contextlib.suppress(Exception):
                            await c.ws.close(1011, "robot session lost")
                    raise BackendError(failure)
        finally:
            for t in tasks:
                t.cancel()
            for sig, prev in taken.items():  # the session's own handlers again: a second signal must not kill it
                loop.remove_signal_handler(sig)
                signal.signal(sig, prev)
        log.info("stopping on %s: the robot glides to rest", signal.Signals(outcome).name)
        deliver_signal(outcome)

    async def _handle(self, ws: Any) -> None:
        from websockets.exceptions import ConnectionClosed

        peer = _peer(ws)
        origin = ws.request.headers.get("Origin") if ws.request is not None else None
        if len(self.connections) >= self.limits.max_clients:
            n = len(self.connections)
            log.warning("refused %s (origin %s): %d clients connected, the most --max-clients allows", peer, origin, n)
            with contextlib.suppress(Exception):
                await ws.send(json.dumps({"type": "error", "message": f"server busy: {n} clients connected, the most "
                                          "it takes (--max-clients); try again later"}))  # fmt: skip
                await ws.close(1013, "server busy")  # 1013: try again later
            return
        conn = _Connection(self, ws, peer)
        self.connections.add(conn)
        log.info("client %s connected (origin %s)", peer, origin)
        await conn.send({"type": "hello", "protocol": PROTOCOL_VERSION, **self.status()})
        if self.lost is not None:
            await conn.send({"type": "session_lost", "message": self.lost})
        try:
            async for msg in ws:
                await conn.dispatch(msg)
        except ConnectionClosed:  # the client went away without a closing handshake: nothing to report
            pass
        finally:
            self.connections.discard(conn)
            self._queues.pop(conn, None)
            self._served.pop(conn, None)
            conn.finish()
            log.info("client %s disconnected", peer)
            await asyncio.to_thread(release_freed_memory)

    def status(self) -> dict:
        st = self.robot.status()
        st["error"] = self.lost or st.get("error")
        st["clients"] = len(self.connections)
        st["says_queued"] = sum(len(q) for q in self._queues.values())
        return st

    async def _broadcast(self, obj: dict) -> None:
        await asyncio.gather(*(c.send(obj) for c in list(self.connections)))

    def check_alive(self, what: str) -> None:
        """Refuse ``what`` (a say or stream) while the session is dead, naming why."""
        if self.lost is not None:
            raise BackendError(f"{what}: refused, the robot session was lost ({self.lost})")

    # --- the robot's health ---------------------------------------------------------------------------
    async def _watch(self) -> None:
        """Notice the session's death at once (not at the next say): log it, tell every client, try once to reopen."""
        while True:
            await asyncio.sleep(_WATCH_S)
            err = self.robot.error
            if err is None:
                continue
            msg = str(err) or type(err).__name__
            self.lost = msg
            log.error("robot session lost: %s", msg)
            await self._broadcast({"type": "session_lost", "message": msg})
            self._drop_queued(f"say: refused, the robot session was lost ({msg})")
            failure = "no reopening"
            if self.reopen is not None:
                log.info("reopening the robot session once")
                with contextlib.suppress(Exception):
                    await asyncio.to_thread(self.robot.close)  # its loop already went to rest; restore BLAS pools
                try:
                    robot = await asyncio.to_thread(self.reopen)
                except Exception as e:
                    failure = f"reopening failed: {e}"
                    log.error("robot session not reopened: %s", e)
                else:
                    self.robot, self.lost = robot, None
                    log.info("robot session reopened")
                    await self._broadcast({"type": "session_restored", **self.status()})
                    continue
            if self._stop is not None and not self._stop.done():
                self._stop.set_result(BackendError(f"robot session lost ({msg}); {failure}"))
            return

    # --- says, round-robin ----------------------------------------------------------------------------
    def enqueue(self, say: _Say) -> None:
        self._queues.setdefault(say.conn, deque()).append(say)
        self._wake.set()

    def _next_say(self) -> _Say | None:
        """The first say of the client served longest ago (never: first), so each client gets its turn."""
        if not self._queues:
            return None
        conn = min(self._queues, key=lambda c: (self._served.get(c, -1), self._queues[c][0].seq))
        q = self._queues[conn]
        say = q.popleft()
        if not q:
            del self._queues[conn]
        self._served[conn] = next(self._turn)
        return say

    def _drop_queued(self, message: str) -> None:
        for q in self._queues.values():
            for say in q:
                say.conn.spawn(say.conn.error(message))
        self._queues.clear()

    async def _serve_says(self) -> None:
        """One say at a time: prepared, then played to its end (or interrupted) before the next client's turn."""
        while True:
            say = self._next_say()
            if say is None:
                self._wake.clear()
                await self._wake.wait()
                continue
            try:
                h = await say.conn.start_say(say)
            except Exception as e:  # a bug must not stop the queue: that client hears of it
                await say.conn.error(f"say: internal error: {type(e).__name__}: {e}")
                continue
            while h is not None and not h.done and self.lost is None:
                await asyncio.sleep(_EVENT_POLL_S)


def _peer(conn: Any) -> str:
    addr = getattr(conn, "remote_address", None)
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)


class _Connection:
    def __init__(self, server: Server, ws: Any, peer: str = "?") -> None:
        self.server = server
        self.ws = ws
        self.peer = peer
        self.stream: Any = None
        self.stream_format = "int16"
        self._fed_n = 0  #: samples fed to the open stream
        self._played_t0: float | None = None  #: time.monotonic() its audio started playing
        self._dropped = 0  #: its chunks refused for the buffer limit
        self.tasks: set[asyncio.Task] = set()

    @property
    def robot(self) -> Any:
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
            obj = _parse(msg)
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
        self.server._interrupts += 1  # says still waiting their turn are dropped
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
        _check_id(obj)
        _body(obj, "say")
        self.server.check_alive("say")
        self.server.enqueue(_Say(self, obj, self.server._interrupts))

    async def start_say(self, say: _Say) -> Any:
        """The say's turn: prepare it and start it playing; its handle (None: dropped or refused, client told)."""
        obj = say.obj
        if self.server._interrupts != say.asked:
            await self.error("say: dropped, an interrupt came before it started")
            return None
        if self.server.lost is not None:
            await self.error(f"say: refused, the robot session was lost ({self.server.lost})")
            return None
        try:  # say() only queues it; it is accepted once prepared (a bad file or tag: an error, not accepted)
            h = self.robot.say(
                obj.get("text"), audio=obj.get("audio"), transcript=obj.get("transcript"), wait=False,
                lenient=obj.get("lenient", False), **_body(obj, "say"),
            )  # fmt: skip
            while not h.prepared:  # polled: the event loop never blocks on it
                await asyncio.sleep(_EVENT_POLL_S / 4)
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
        _check_id(obj)
        body = _body(obj, "stream_start")
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

    def _buffered_s(self, more_n: int) -> float:
        """Seconds of the open stream's audio ahead of what has played, with ``more_n`` samples more."""
        st = self.stream
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
        ahead = self._buffered_s(len(data) // width)
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
        stream = self.stream
        self._close_stream_state()
        log.info("%s: stream utterance %d ended (%.1f s of audio)", self.peer, stream.handle.id,
                 stream._offset_n / stream.sample_rate)  # fmt: skip
        await asyncio.to_thread(stream.close)

    def _close_stream_state(self) -> None:
        self.stream, self._fed_n, self._played_t0 = None, 0, None

    # --- events ---------------------------------------------------------------------------------------
    def spawn(self, coro: Any) -> None:
        t = asyncio.ensure_future(coro)
        self.tasks.add(t)
        t.add_done_callback(self.tasks.discard)

    async def _pump(self, h: Any) -> None:
        """Push the utterance's events as they happen, until it is done."""
        seen: set[tuple] = set()
        while True:
            done = h.done
            for e in h.events:
                key = (e["type"], e["t_monotonic_s"], e.get("offset_s"))
                if key not in seen:
                    seen.add(key)
                    await self.send({"type": "event", "utterance": h.id, "event": e["type"], **_plain(e)})
            if done:
                log.info("%s: utterance %d %s", self.peer, h.id, "interrupted" if h.interrupted else "done")
                await asyncio.to_thread(release_freed_memory)
                return
            await asyncio.sleep(_EVENT_POLL_S)


#: glibc's ``M_MMAP_THRESHOLD`` option of ``mallopt`` (malloc.h) and the value serve sets: blocks this large get
#: their own mapping, returned to the system when freed.
_M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 256 * 1024


def map_large_blocks() -> None:
    """Have glibc give every block of :data:`MMAP_THRESHOLD_BYTES` or more its own mapping (elsewhere nothing).

    Its default threshold rises after each large block freed, up to 32 MB, so a stream's growing audio and feature
    arrays (19 MB of audio for 300 s, copied as it grows) end up in the heap, where they stay fragmented after the
    stream ends; mapped, they go back to the system as soon as they are freed."""
    with contextlib.suppress(Exception):  # not glibc
        ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)


def release_freed_memory() -> None:
    """Give the free pages of the C heap back to the system (glibc's ``malloc_trim``; elsewhere nothing).

    An utterance's arrays, freed when it ends, otherwise stay in the process's arenas: 150 s of streamed speech
    left 41 MB resident, 2 MB after this (about 4 ms; ctypes releases the GIL meanwhile)."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except Exception:  # not glibc
        return
    trim(0)


def _parse(msg: str) -> dict:
    """A text frame as a JSON object with a string ``type``; InputError naming what is wrong, whatever the input
    (Python's decoder raises RecursionError on deep nesting and ValueError on integers of over 4300 digits)."""
    try:
        obj = json.loads(msg)
    except json.JSONDecodeError as e:
        raise InputError(f"not JSON ({e.msg} at character {e.pos}); send one JSON object per text frame") from None
    except RecursionError:
        raise InputError("JSON nested too deeply to decode; send one flat JSON object per text frame") from None
    except ValueError as e:  # "Exceeds the limit (4300 digits) for integer string conversion"
        why = str(e).split(";")[0]
        raise InputError(f"JSON with a number too long to decode ({why}); send plain numbers") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("type"), str):
        raise InputError('a message must be a JSON object with a string "type"')
    return obj


def _check_id(obj: dict) -> None:
    """The ``id`` echoed back: a string, an integer that fits 64 bits, or absent."""
    i = obj.get("id")
    if i is None or (isinstance(i, str) and len(i) <= 256) or (type(i) is int and abs(i) < 2**63):
        return
    raise InputError('"id" must be a string of at most 256 characters or an integer of 64 bits')


def _body(obj: dict, what: str) -> dict:
    """The message's per-utterance body language (``style``, ``amount``, ``gestures``), checked: InputError naming
    the field."""
    from robogest.live.style import body_language

    body = {k: obj[k] for k in ("style", "amount", "gestures") if obj.get(k) is not None}
    body_language(**body, what=what)
    return body


def _plain(e: dict) -> dict:
    return {k: (float(v) if hasattr(v, "__float__") and not isinstance(v, bool | int) else v) for k, v in e.items()
            if k != "type"}  # fmt: skip


def serve_forever(server: Server, robot_name: str, backend: str) -> None:
    """Run ``server`` in this thread until SIGINT/SIGTERM (which the robot's session turns into a rest + exit) or the
    session's death (BackendError)."""

    def ready(h: str, p: int) -> None:
        print(f"robogest serve: ready on ws://{h}:{p} (robot {robot_name}, backend {backend})", flush=True)

    map_large_blocks()
    try:
        asyncio.run(server.run(ready))
    finally:
        sys.stdout.flush()
