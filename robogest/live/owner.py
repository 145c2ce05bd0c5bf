"""The thread that owns a live session's utterance state: what plays, the says being prepared, the speech audio,
the open streams.

Every change to that state is a message (a function) run here, one at a time in the order posted, so the session
needs no lock for it: a say registers, an interrupt cancels and starts the glide to rest, a prepared say or a
stream's first frames start playing, close cancels. Messages are short (no preparation or planning runs here:
says are prepared by the session's worker, streams planned in their own threads), so an interrupt is handled at
once. After :meth:`Owner.stop` messages run in the caller's thread (the session is closed: nothing competes).
"""

from __future__ import annotations

import queue
import sys
import threading
import traceback
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")
_STOP = object()


class _Reply:
    """The outcome of a :meth:`Owner.call`, handed from the owner's thread to the caller's."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.value: Any = None
        self.error: BaseException | None = None


class Owner:
    """Runs posted messages in order in one daemon thread (see module docstring)."""

    def __init__(self, name: str) -> None:
        self._queue: queue.SimpleQueue[object] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, daemon=True, name=name)
        self._stopped = False

    def start(self) -> None:
        self._thread.start()

    def post(self, message: Callable[[], object]) -> None:
        """Run ``message`` after the ones posted before it; returns at once. A failure is printed (a bug)."""
        if self._stopped or threading.current_thread() is self._thread:
            _run_reporting(message)
            return
        self._queue.put(message)

    def call(self, message: Callable[[], T]) -> T:
        """Run ``message`` after the ones posted before it and return its result (or raise its exception)."""
        if self._stopped or threading.current_thread() is self._thread or not self._thread.is_alive():
            return message()
        reply = _Reply()

        def run() -> None:
            try:
                reply.value = message()
            except BaseException as e:  # handed to the caller
                reply.error = e
            finally:
                reply.done.set()

        self._queue.put(run)
        while not reply.done.wait(0.05):  # short waits: signals reach the main thread between them
            if not self._thread.is_alive() and not reply.done.is_set():  # stopped meanwhile: it would never run
                return message()
        if reply.error is not None:
            raise reply.error
        value: T = reply.value
        return value

    def stop(self, timeout_s: float = 10.0) -> None:
        """Run the messages already posted, then end the thread; later ones run in their caller's thread."""
        self._queue.put(_STOP)
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self._stopped = True
        while not self._queue.empty():  # posted while it stopped
            message = self._queue.get()
            if message is not _STOP and callable(message):
                _run_reporting(message)

    def _run(self) -> None:
        while True:
            message = self._queue.get()
            if message is _STOP:
                return
            assert callable(message)
            _run_reporting(message)
            del message  # what it holds (a finished stream, its audio) must not wait for the next message


def _run_reporting(message: Callable[[], object]) -> None:
    try:
        message()
    except Exception:  # a bug in a message: say so, keep the session's state owner alive
        print("robogest: a live-session state change failed:", file=sys.stderr)
        traceback.print_exc()
