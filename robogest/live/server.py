"""``robogest serve``: one :class:`~robogest.live.Robot` session behind a local WebSocket server.

Protocol (version 1). Text frames are JSON objects with a ``type``; binary frames are PCM of the open stream.

Client -> server:

* ``{"type": "say", "text": "..."}`` or ``{"type": "say", "audio": "/path.wav", "transcript": "/path.TextGrid"}``
  (files on the server's machine); optional ``"id"`` is echoed back;
* ``{"type": "stream_start", "sample_rate": 16000, "format": "int16"}`` (or ``"float32"``), then binary frames of
  mono little-endian PCM (10-100 ms each), optional ``{"type": "words", "words": [["hello", 0.0, 0.31], ...]}``
  (seconds from the stream's start), then ``{"type": "stream_end"}``;
* ``{"type": "interrupt"}``: stop now, glide to rest;
* ``{"type": "status"}``.

Server -> client: ``{"type": "hello", "protocol": 1, ...status}`` on connect; ``{"type": "accepted", "utterance": N,
"id": ...}`` for each say/stream; ``{"type": "event", "utterance": N, "event": "first_goal", "t_monotonic_s": ...}``
for every utterance event (``audio_chunk`` events carry ``offset_s`` and the play time when the server cannot play
audio itself); ``{"type": "interrupted", "interrupt_s": ..., "at_rest_s": ...}``; ``{"type": "status", ...}``;
``{"type": "error", "message": "..."}`` for anything malformed (the session keeps running).

Security: it listens on 127.0.0.1 by default; another address needs a token (``Authorization: Bearer T`` header
or ``?token=T``). A WebSocket handshake with an ``Origin`` header (every browser sends one) is refused unless that
origin was allowed explicitly, so a web page cannot move the robot.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import signal
import sys
from collections.abc import Sequence
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qs, urlsplit

from robogest.errors import InputError, RobogestError

PROTOCOL_VERSION = 1
_EVENT_POLL_S = 0.02


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


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class Server:
    """Serves ``robot`` (an open :class:`Robot`) on ``host:port`` (see module docstring)."""

    def __init__(
        self, robot: Any, host: str, port: int, *, token: str | None = None, allow_origins: Sequence[str] = ()
    ) -> None:
        if not is_loopback(host) and not token:
            raise InputError(
                f"--listen {host}:{port} is not a loopback address: anyone who reaches it could move the robot; "
                "add --token SECRET (clients send 'Authorization: Bearer SECRET')"
            )
        self.robot = robot
        self.host, self.port = host, port
        self.token = token
        self.origins: list[str | None] = [None, *allow_origins]
        #: One robot: utterances from every client are prepared one at a time, in the order they came (a fair
        #: asyncio lock, so waiting ones hold no worker thread and an interrupt never queues behind them).
        self._say_lock = asyncio.Lock()
        self._interrupts = 0  #: interrupts so far: a say that came before one is dropped, not started after it

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
        return connection.respond(HTTPStatus.UNAUTHORIZED, "missing or wrong token\n")

    # --- session --------------------------------------------------------------------------------------
    async def run(self, ready: Any = None) -> None:
        """Serve until cancelled or SIGINT/SIGTERM/SIGHUP; ``ready(host, port)`` once listening.

        The event loop takes those signals itself (a Python signal handler would raise inside whichever task
        happens to run) and raises :class:`~robogest.backends.control.Interrupted` from here, so the session
        ends at rest and the process exits with 128 + the signal number.
        """
        from websockets.asyncio.server import serve

        from robogest.backends.control import deliver_signal

        loop = asyncio.get_running_loop()
        stop: asyncio.Future = loop.create_future()
        taken: dict[int, Any] = {}
        for name in ("SIGINT", "SIGTERM", "SIGHUP"):
            sig = getattr(signal, name, None)
            prev = signal.getsignal(sig) if sig is not None else None
            if sig is None or (name == "SIGHUP" and prev == signal.SIG_IGN):
                continue
            try:
                loop.add_signal_handler(sig, lambda s=sig: stop.done() or stop.set_result(s))
            except (NotImplementedError, RuntimeError, ValueError):  # not the main thread, or no such support
                continue
            taken[sig] = prev
        try:
            async with serve(
                self._handle, self.host, self.port, origins=self.origins, process_request=self._check_token,
                max_size=2**22,
            ) as server:  # fmt: skip
                sock = next(iter(server.sockets))
                self.port = sock.getsockname()[1]
                if ready is not None:
                    ready(self.host, self.port)
                signum = await stop
        finally:
            for sig, prev in taken.items():  # the session's own handlers again: a second signal must not kill it
                loop.remove_signal_handler(sig)
                signal.signal(sig, prev)
        deliver_signal(signum)

    async def _handle(self, ws: Any) -> None:
        conn = _Connection(self, ws)
        await conn.send({"type": "hello", "protocol": PROTOCOL_VERSION, **self.robot.status()})
        from websockets.exceptions import ConnectionClosed

        try:
            async for msg in ws:
                await conn.dispatch(msg)
        except ConnectionClosed:  # the client went away without a closing handshake: nothing to report
            pass
        finally:
            conn.finish()


class _Connection:
    def __init__(self, server: Server, ws: Any) -> None:
        self.server = server
        self.robot = server.robot
        self.ws = ws
        self.stream: Any = None
        self.stream_format = "int16"
        self.tasks: set[asyncio.Task] = set()

    async def send(self, obj: dict) -> None:
        with contextlib.suppress(Exception):  # the client may be gone; the robot carries on
            await self.ws.send(json.dumps(obj))

    async def error(self, message: str) -> None:
        await self.send({"type": "error", "message": message})

    def finish(self) -> None:
        for t in self.tasks:
            t.cancel()
        if self.stream is not None:  # a client that vanished mid-stream: finish what it said
            with contextlib.suppress(Exception):
                self.stream.close()

    async def dispatch(self, msg: str | bytes) -> None:
        try:
            if isinstance(msg, bytes):
                await self._pcm(msg)
                return
            try:
                obj = json.loads(msg)
            except json.JSONDecodeError as e:
                raise InputError(
                    f"not JSON ({e.msg} at character {e.pos}); send one JSON object per text frame"
                ) from None
            if not isinstance(obj, dict) or not isinstance(obj.get("type"), str):
                raise InputError('a message must be a JSON object with a string "type"')
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
            await self.error(f"internal error: {type(e).__name__}: {e}")

    # --- messages -------------------------------------------------------------------------------------
    async def _on_status(self, obj: dict) -> None:
        await self.send({"type": "status", **self.robot.status()})

    async def _on_interrupt(self, obj: dict) -> None:
        self.server._interrupts += 1  # says still waiting their turn are dropped
        res = await asyncio.to_thread(self.robot.interrupt)
        self.stream = None
        await self.send({"type": "interrupted", **res})

    async def _on_say(self, obj: dict) -> None:
        text, audio, transcript = obj.get("text"), obj.get("audio"), obj.get("transcript")
        for key, v in (("text", text), ("audio", audio), ("transcript", transcript)):
            if v is not None and not isinstance(v, str):
                raise InputError(f'say: "{key}" must be a string')

        asked = self.server._interrupts

        async def run() -> None:
            async with self.server._say_lock:
                if self.server._interrupts != asked:
                    await self.error("say: dropped, an interrupt came before it started")
                    return
                try:
                    h = await asyncio.to_thread(self.robot.say, text, audio=audio, transcript=transcript, wait=False)
                except RobogestError as e:
                    await self.error(f"say: {e}")
                    return
            await self.send({"type": "accepted", "utterance": h.id, "id": obj.get("id")})
            await self._pump(h)

        self._spawn(run())

    async def _on_stream_start(self, obj: dict) -> None:
        sr, fmt = obj.get("sample_rate", 16000), obj.get("format", "int16")
        if not isinstance(sr, int) or isinstance(sr, bool):
            raise InputError('stream_start: "sample_rate" must be an integer, Hz')
        if fmt not in ("int16", "float32"):
            raise InputError(f'stream_start: "format" {fmt!r} is not supported; use "int16" or "float32"')
        if self.stream is not None:
            await asyncio.to_thread(self.stream.close)
        self.stream = await asyncio.to_thread(self.robot.stream, sr)
        self.stream_format = fmt
        h = self.stream.handle
        await self.send({"type": "accepted", "utterance": h.id, "id": obj.get("id")})
        self._spawn(self._pump(h))

    async def _pcm(self, data: bytes) -> None:
        if self.stream is None:
            raise InputError('binary PCM without an open stream; send {"type": "stream_start"} first')
        from robogest.speech.stream import pcm_to_float

        width = 2 if self.stream_format == "int16" else 4
        if len(data) % width:
            raise InputError(f"PCM frame of {len(data)} bytes is not a whole number of {self.stream_format} samples")
        chunk = pcm_to_float(data, self.stream_format)
        await asyncio.to_thread(self.stream.feed, chunk)

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
        stream, self.stream = self.stream, None
        await asyncio.to_thread(stream.close)

    # --- events ---------------------------------------------------------------------------------------
    def _spawn(self, coro: Any) -> None:
        t = asyncio.ensure_future(coro)
        self.tasks.add(t)
        t.add_done_callback(self.tasks.discard)

    async def _pump(self, h: Any) -> None:
        """Push the utterance's events as they happen, until it is done."""
        sent: set[tuple] = set()
        while True:
            done = h.done
            for e in h.events:
                key = (e["type"], e["t_monotonic_s"], e.get("offset_s"))
                if key not in sent:
                    sent.add(key)
                    await self.send({"type": "event", "utterance": h.id, "event": e["type"], **_plain(e)})
            if done:
                return
            await asyncio.sleep(_EVENT_POLL_S)


def _plain(e: dict) -> dict:
    return {k: (float(v) if hasattr(v, "__float__") and not isinstance(v, bool | int) else v) for k, v in e.items()
            if k != "type"}  # fmt: skip


def serve_forever(robot: Any, host: str, port: int, *, token: str | None, allow_origins: Sequence[str]) -> None:
    """Run the server in this thread until SIGINT/SIGTERM (which the robot's session turns into a rest + exit)."""
    server = Server(robot, host, port, token=token, allow_origins=allow_origins)

    def ready(h: str, p: int) -> None:
        print(f"robogest serve: ready on ws://{h}:{p} (robot {robot.config.name}, backend {robot.backend_name})",
              flush=True)  # fmt: skip

    try:
        asyncio.run(server.run(ready))
    except OSError as e:
        raise InputError(f"--listen {host}:{port}: cannot listen there ({e.strerror or e})") from None
    finally:
        sys.stdout.flush()
