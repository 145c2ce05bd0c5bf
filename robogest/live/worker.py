"""The session's worker: one thread that gets the session ready, then prepares its says in order.

``say(wait=False)`` only queues a job here, so it returns at once whatever the text's length; text-to-speech, the
generator and the safety layer run in this thread. Jobs run one at a time in the order given, after the start-up
job (idle motion, warm-up): a say asked for before the session is ready waits for it instead of competing with it
for the cores.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

_STOP = object()


class Worker:
    """Runs ``startup`` then every :meth:`submit`-ted job, in order, in one daemon thread."""

    def __init__(self, startup: Callable[[], None], name: str) -> None:
        self.ready = threading.Event()  #: set once ``startup`` has run (or failed, or the worker was stopped)
        self.stopping = threading.Event()
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._startup = startup
        self._lock = threading.Lock()  # a job is queued before the stop marker, or dropped at once
        self._thread = threading.Thread(target=self._run, daemon=True, name=name)

    def start(self) -> None:
        self._thread.start()

    def submit(self, job: Callable[[], None], drop: Callable[[], None]) -> None:
        """Run ``job`` after the ones before it, or ``drop`` it if the worker stops first (each must report its
        own failures: nothing here raises)."""
        with self._lock:
            if not self.stopping.is_set():
                self._jobs.put((job, drop))
                return
        drop()

    def stop(self, timeout_s: float | None = 60.0) -> None:
        """Drop the jobs not started and end the thread; waits for the job running (up to ``timeout_s``).

        Joined, not left running: a daemon thread still inside numba or NumPy code while the interpreter finalizes
        can crash the process at exit."""
        with self._lock:
            self.stopping.set()
            self._jobs.put(_STOP)
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    def _run(self) -> None:
        try:
            if not self.stopping.is_set():
                self._startup()
        except Exception:  # the start-up is an optimisation: a failure only leaves the first say slower
            pass
        finally:
            self.ready.set()
        while True:
            item = self._jobs.get()
            if item is _STOP:
                return
            job, drop = item
            (drop if self.stopping.is_set() else job)()
