"""What the control loop hands back for a motion it plays: :class:`PlayHandle` (its :class:`Event` stamps, a way to
wait for it) and the loop's tick timing (:class:`LoopStats`). Re-exported by :mod:`robogest.backends.control`."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class Playable(Protocol):
    """What the loop plays: a :class:`~robogest.trajectory.Trajectory`, or a
    :class:`~robogest.live.planner.TrajectoryFeed` that grows while it plays. Poses ``(J,)`` radians."""

    @property
    def duration_s(self) -> float: ...

    def sample(self, t_s: float) -> np.ndarray: ...

    def sample_velocity(self, t_s: float) -> np.ndarray: ...


class _Loop(Protocol):
    """What a handle needs of its :class:`~robogest.backends.control.ControlLoop`."""

    def _wait(self, h: PlayHandle, timeout_s: float | None) -> None: ...


@dataclass
class Event:
    """Something that happened in the loop: ``time.monotonic()`` and loop-clock stamps, seconds."""

    name: str
    monotonic_s: float
    loop_s: float


class PlayHandle:
    """A motion given to the loop (a trajectory, or the glide to rest after :meth:`ControlLoop.interrupt`).

    Events (:attr:`events`, by name): ``started`` (trajectory time 0 reached; after the glide to its first pose),
    ``first_goal`` (first goal sent that departs from the pose held before), ``done`` (the trajectory ended and
    the goal settled on its last pose; for a rest handle: at rest), ``interrupted`` (replaced or interrupted).
    """

    def __init__(
        self, loop: _Loop, trajectory: Playable | None, start_at: float | None, approach_within_rad: float = 0.0
    ) -> None:
        self._loop = loop
        self.trajectory = trajectory
        self.start_at = start_at
        self.approach_within_rad = approach_within_rad
        self.events: dict[str, Event] = {}
        self._finished = threading.Event()
        self.error: BaseException | None = None
        self.on_start: Callable[[], None] | None = None
        self.progress: Callable[[float, float], None] | None = None
        # playback state, owned by the loop
        self.phase = "wait"  # wait -> approach -> run -> finish -> done | interrupted
        self.t_run0 = 0.0
        self.held: np.ndarray | None = None

    @property
    def done(self) -> bool:
        """True once the motion ended, by completion, interruption or a loop failure."""
        return self._finished.is_set()

    @property
    def completed(self) -> bool:
        return "done" in self.events

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until :attr:`done` (stepped loops tick here); re-raise a loop failure. Returns :attr:`done`."""
        self._loop._wait(self, timeout_s)
        if self.error is not None:
            raise self.error
        return self.done

    def _mark(self, name: str, loop_s: float) -> None:
        if name not in self.events:
            self.events[name] = Event(name, time.monotonic(), loop_s)
        if name in ("done", "interrupted"):
            self._finished.set()

    def _fail(self, e: BaseException) -> None:
        self.error = e
        self._finished.set()


@dataclass
class LoopStats:
    """Timing of the ticks: wall-clock start of each (``time.monotonic()``, seconds; the last hour's at 100 Hz, so
    a session that runs for days does not grow by 11 MB an hour), late and skipped counts."""

    n_ticks: int = 0
    starts: deque[float] = field(default_factory=lambda: deque(maxlen=360_000))
    late_ticks: int = 0
    skipped_slots: int = 0
