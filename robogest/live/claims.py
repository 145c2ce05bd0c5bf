"""One session per robot: the claims of open :class:`~robogest.live.Robot` sessions, and their close at exit.

A servo bus is claimed by its port: in this process by the table here (refused before anything is opened), in
other processes by the exclusive lock the servo backends take on the port (``open_port_exclusive``). A simulated
robot is claimed by its name within this process only: two processes may each simulate the same robot (test runs,
benchmarks and demos side by side on one machine have nothing to share), but one process holding two sessions of
one robot is a mistake (two control loops driving the same model).

Sessions left open when the interpreter exits are closed by an ``atexit`` hook: the robot glides to rest and torque
goes off (a daemon control thread would otherwise just stop, torque on), and the session drops its native
objects before the interpreter tears the extension modules down (nanobind reports objects still alive then as
"leaked").
"""

from __future__ import annotations

import atexit
import contextlib
import os
import threading
import weakref
from typing import Any

from robogest.errors import BackendError

_lock = threading.Lock()
_claims: dict[tuple[str, str], Any] = {}  #: (backend kind, robot name or port) -> the open session
_sessions: weakref.WeakSet = weakref.WeakSet()  #: every session claimed in this process (closed or not)
_hooked = False


def claim_key(backend: str, robot_name: str, port: str | None) -> tuple[str, str]:
    """``("sim", robot name)`` for the simulator, ``("port", real path)`` for a servo bus."""
    if backend == "sim" or not port:
        return (backend, robot_name)
    return ("port", os.path.realpath(port))


def claim(key: tuple[str, str], session: Any) -> None:
    """Record ``session`` as the one on ``key``; BackendError (one line) when another holds it."""
    global _hooked
    with _lock:
        other = _claims.get(key)
        if other is not None and other is not session and other._holds_robot():  # a dead one is taken over
            kind, name = key
            what = f"serial port {name}" if kind == "port" else f"robot {name} ({kind})"
            raise BackendError(
                f"{what} already has an open session in this process; close() it (or use the one open) before "
                "opening another"
            )
        _claims[key] = session
        _sessions.add(session)
        if not _hooked:
            atexit.register(close_all)
            _hooked = True


def release(key: tuple[str, str] | None, session: Any) -> None:
    with _lock:
        if key is not None and _claims.get(key) is session:
            del _claims[key]


def close_all() -> None:
    """At interpreter exit: close every session still open (glide to rest, torque off), then free the native
    objects of every session."""
    with _lock:
        open_now = list(_claims.values())
        every = list(_sessions)
    for session in open_now:
        with contextlib.suppress(Exception):
            session.close()
    for session in every:
        with contextlib.suppress(Exception):
            session._release_native()
