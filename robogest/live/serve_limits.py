"""What one ``robogest serve`` accepts and where it listens (:mod:`robogest.live.server`): the limits, the listening
address and its token rule, the socket bound before the robot is opened, and the C heap it gives back."""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import socket
from dataclasses import dataclass

from robogest.errors import InputError

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
        code = e.errno
        why = os.strerror(code) if code is not None and code > 0 else (e.strerror or str(e))  # gaierror: negative
        raise InputError(f"--listen {host}:{port}: cannot listen there ({why}); {fix}") from None


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
