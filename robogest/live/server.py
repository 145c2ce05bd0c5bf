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
import hmac
import itertools
import json
import logging
import signal
import socket
import sys
from collections import deque
from collections.abc import Callable, Sequence
from http import HTTPStatus
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from robogest.errors import BackendError
from robogest.live.serve_connection import EVENT_POLL_S, Connection, Say, peer_of
from robogest.live.serve_limits import (
    ServeLimits,
    check_token,
    map_large_blocks,
    release_freed_memory,
)
from robogest.live.serve_messages import PROTOCOL_VERSION

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection
    from websockets.http11 import Request, Response

    from robogest.live.session import Robot

log = logging.getLogger(__name__)

_WATCH_S = 0.05  #: how often the session's health is checked


class Server:
    """Serves ``robot`` (an open :class:`Robot`) on ``sock`` or ``host:port`` (see module docstring).

    ``reopen``: called once (in a worker thread) after the session died, returns a new open Robot; None, or a
    failure, ends :meth:`run` with a :class:`~robogest.errors.BackendError` (exit 5).
    """

    def __init__(
        self,
        robot: Robot,
        host: str,
        port: int,
        *,
        token: str | None = None,
        allow_origins: Sequence[str] = (),
        limits: ServeLimits | None = None,
        sock: socket.socket | None = None,
        reopen: Callable[[], Robot] | None = None,
    ) -> None:
        check_token(host, port, token)
        self.robot = robot
        self.host, self.port = host, port
        self.sock = sock
        self.token = token
        self.allow_origins = tuple(allow_origins)  #: besides handshakes without an Origin (not from a browser)
        self.limits = limits or ServeLimits()
        self.reopen = reopen
        self.connections: set[Connection] = set()
        #: Says waiting, per client (none empty), and the turn in which each client was last served (round-robin).
        self._queues: dict[Connection, deque[Say]] = {}
        self._served: dict[Connection, int] = {}
        self._turn = itertools.count()
        self._wake = asyncio.Event()
        self.interrupts = 0  #: interrupts so far: a say that came before one is dropped, not started after it
        self.lost: str | None = None  #: why the robot's session died (None while it lives)
        self._stop: asyncio.Future | None = None

    # --- handshake ------------------------------------------------------------------------------------
    def _check_token(self, connection: ServerConnection, request: Request) -> Response | None:
        if not self.token:
            return None
        auth = request.headers.get("Authorization", "")
        scheme, _, value = auth.partition(" ")
        given = value.strip() if scheme.lower() == "bearer" else ""  # the scheme is case-insensitive (RFC 7235)
        if not given:
            given = (parse_qs(urlsplit(request.path).query).get("token") or [""])[0]
        if given and hmac.compare_digest(given.encode(), self.token.encode()):
            return None
        log.warning("refused %s: missing or wrong token", peer_of(connection))
        return connection.respond(HTTPStatus.UNAUTHORIZED, "missing or wrong token\n")

    # --- session --------------------------------------------------------------------------------------
    async def run(self, ready: Callable[[str, int], None] | None = None) -> None:
        """Serve until cancelled, SIGINT/SIGTERM/SIGHUP/SIGQUIT, or the session's death; ``ready(host, port)`` once
        listening.

        The event loop takes those signals itself (a Python signal handler would raise inside whichever task
        happens to run) and raises :class:`~robogest.backends.signals.Interrupted` from here, so the session
        ends at rest and the process exits with 128 + the signal number. A session that died and could not be
        reopened raises :class:`~robogest.errors.BackendError` (exit 5), also when a signal comes meanwhile.
        """
        from websockets.asyncio.server import serve
        from websockets.typing import Origin

        from robogest.backends.signals import HANDLED_SIGNALS, deliver_signal

        loop = asyncio.get_running_loop()
        stop: asyncio.Future = loop.create_future()
        self._stop = stop

        def stop_on(sig: int) -> None:
            if not stop.done():
                stop.set_result(sig)

        taken: dict[int, Any] = {}
        for name in HANDLED_SIGNALS:
            sig = getattr(signal, name, None)
            prev = signal.getsignal(sig) if sig is not None else None
            if sig is None or (name == "SIGHUP" and prev == signal.SIG_IGN):
                continue
            try:
                loop.add_signal_handler(sig, stop_on, sig)
            except (NotImplementedError, RuntimeError, ValueError):  # not the main thread, or no such support
                continue
            taken[sig] = prev
        where: dict[str, Any] = {"sock": self.sock} if self.sock is not None else {"host": self.host, "port": self.port}
        tasks: list[asyncio.Task] = []
        try:
            async with serve(
                self._handle, origins=[None, *map(Origin, self.allow_origins)], process_request=self._check_token,
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

    async def _handle(self, ws: ServerConnection) -> None:
        from websockets.exceptions import ConnectionClosed

        peer = peer_of(ws)
        origin = ws.request.headers.get("Origin") if ws.request is not None else None
        if len(self.connections) >= self.limits.max_clients:
            n = len(self.connections)
            log.warning("refused %s (origin %s): %d clients connected, the most --max-clients allows", peer, origin, n)
            with contextlib.suppress(Exception):
                await ws.send(json.dumps({"type": "error", "message": f"server busy: {n} clients connected, the most "
                                          "it takes (--max-clients); try again later"}))  # fmt: skip
                await ws.close(1013, "server busy")  # 1013: try again later
            return
        conn = Connection(self, ws, peer)
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
    def enqueue(self, say: Say) -> None:
        self._queues.setdefault(say.conn, deque()).append(say)
        self._wake.set()

    def _next_say(self) -> Say | None:
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
                await asyncio.sleep(EVENT_POLL_S)


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
