"""What every utterance of a live session returns: :class:`UtteranceHandle` (its events, waiting for it).

Events are dicts with ``type`` (:data:`EVENT_TYPES`) and ``t_monotonic_s`` (``time.monotonic()``).
"""

from __future__ import annotations

import itertools
import threading
import time
from typing import Any

from robogest.backends.play_handle import PlayHandle

#: Event types an utterance can report, in the order they usually happen.
EVENT_TYPES = ("requested", "first_chunk", "first_goal", "started", "audio_start", "done", "interrupted", "error")
_ids = itertools.count(1)


class UtteranceHandle:
    """One utterance given to a :class:`Robot`: its events, and a way to wait for it.

    ``events``: dicts with ``type`` (see :data:`EVENT_TYPES`; also ``audio_chunk`` when the session cannot
    play audio itself: ``offset_s`` into the utterance and the ``t_monotonic_s`` it should start playing) and
    ``t_monotonic_s``; ``first_goal`` is the first goal sent that departs from the pose held before.
    """

    def __init__(self, kind: str) -> None:
        self.id = next(_ids)
        self.kind = kind
        self._own: list[dict] = []
        self._lock = threading.Lock()
        self._attached = threading.Event()
        self._play: PlayHandle | None = None
        self._abandoned = False
        self._error: BaseException | None = None
        self.trajectory: Any = None  #: the Trajectory played (or the growing feed of a stream)

    def _add(self, type_: str, t: float | None = None, **extra: Any) -> None:
        with self._lock:
            self._own.append({"type": type_, "t_monotonic_s": time.monotonic() if t is None else t, **extra})

    def _attach(self, play: Any) -> None:
        self._play = play
        self._attached.set()

    def _abandon(self, why: str) -> None:
        """Nothing will be played (e.g. interrupted before the first motion was planned; the caller resumes idle)."""
        with self._lock:
            if self._abandoned:  # once (an interrupt finishes a say being prepared, whose worker then gives up too)
                return
        self._abandoned = True
        self._add("interrupted", reason=why)
        self._attached.set()

    def _fail(self, e: BaseException) -> None:
        """Its preparation failed: an ``error`` event (``message``), :meth:`wait` raises ``e``; nothing plays."""
        self._error = e
        self._abandoned = True
        self._add("error", message=str(e) or type(e).__name__)
        self._attached.set()

    @property
    def play_handle(self) -> PlayHandle | None:
        """The control loop's handle of its motion, once handed to the robot (None before, or if abandoned)."""
        return self._play

    @property
    def error(self) -> BaseException | None:
        """Why the utterance could not be prepared (bad input, unknown gesture tag...), or None."""
        return self._error

    @property
    def events(self) -> list[dict]:
        """All events so far, ordered by time."""
        with self._lock:
            out = list(self._own)
        if self._play is not None:
            for name, ev in list(self._play.events.items()):
                out.append({"type": name, "t_monotonic_s": ev.monotonic_s})
        return sorted(out, key=lambda e: e["t_monotonic_s"])

    def event(self, type_: str) -> dict | None:
        """The first event of ``type_``, or None."""
        return next((e for e in self.events if e["type"] == type_), None)

    @property
    def done(self) -> bool:
        """Finished: played to the end, interrupted, or failed."""
        return self._abandoned or (self._play is not None and self._play.done)

    @property
    def interrupted(self) -> bool:
        return self.event("interrupted") is not None

    def wait_started(self, timeout_s: float | None = None) -> bool:
        """Block until the utterance is prepared and handed to the robot, or abandoned (False on ``timeout_s``);
        raises its preparation's failure."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        step = 0.05  # short waits: signals reach the main thread between them
        while not self._attached.wait(step if deadline is None else max(0.0, min(step, deadline - time.monotonic()))):
            if deadline is not None and time.monotonic() >= deadline:
                return False
        if self._error is not None:
            raise self._error
        return True

    @property
    def prepared(self) -> bool:
        """Handed to the robot, abandoned or failed: :meth:`wait_started` would return at once."""
        return self._attached.is_set()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until :attr:`done` (or ``timeout_s``); raises a failure of its preparation or of the backend.
        Returns :attr:`done`."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        if not self.wait_started(timeout_s):
            return False
        if self._play is None:
            return True
        left = None if deadline is None else max(0.0, deadline - time.monotonic())
        return bool(self._play.wait(left))
