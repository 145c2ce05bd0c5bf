"""Signals that end motion at rest: SIGINT, SIGTERM, SIGHUP and SIGQUIT become :class:`Interrupted` (a
KeyboardInterrupt) once, raised between control ticks, never inside one (:func:`deferred_signals`); later ones are
recorded and ignored so they cannot cut the glide to rest short. Used by the control loop
(:mod:`robogest.backends.control`, which re-exports these names), the CLI, a live session and ``robogest serve``.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM, SIGHUP or SIGQUIT arrived: the robot is taken to rest and torque turned off on the way out.

    A :class:`KeyboardInterrupt` (so ``except Exception`` never swallows it); ``exit_code`` is ``128 + signum``;
    ``outcome`` is filled in once the shutdown has run (at rest with torque off, or why not).
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)
        self.signal_name = signal.Signals(signum).name
        self.exit_code = 128 + self.signum
        self.outcome = ""

    def __str__(self) -> str:
        return f"interrupted by {self.signal_name}" + (f"; {self.outcome}" if self.outcome else "")


class _SignalState:
    def __init__(self) -> None:
        self.active = 0
        self.fired: Interrupted | None = None
        self.pending: int | None = None
        self.critical = 0
        self.later: list[str] = []  #: signals that arrived after the first (they do not cut the glide short)


_SIG = _SignalState()
#: Signals that end motion at rest with torque off (exit 128 + signal), in the CLI, a live session and ``serve``;
#: SIGQUIT (Ctrl-\) too: its default ends the process at once, torque left on.
HANDLED_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")


def _on_signal(signum: int, frame: Any) -> None:
    if _SIG.fired is not None or _SIG.pending is not None:
        # Already on the way to rest, as fast as the limits allow; stopping now would drop the arms.
        _SIG.later.append(signal.Signals(signum).name)
        return
    if _SIG.critical:  # inside a tick: raised at its end, so goal and limiter state never disagree
        _SIG.pending = signum
        return
    _SIG.fired = Interrupted(signum)
    raise _SIG.fired


def deliver_signal(signum: int) -> None:
    """Act on ``signum`` now, in this thread, as :func:`signals_end_at_rest` would on its arrival (raise
    :class:`Interrupted` once, ignore later ones): for an event loop that catches signals itself so that none is
    raised inside one of its tasks."""
    _on_signal(signum, None)


def _raise_pending() -> None:
    if _SIG.pending is not None and _SIG.fired is None and not _SIG.critical:
        _SIG.fired = Interrupted(_SIG.pending)
        raise _SIG.fired


@contextlib.contextmanager
def signals_end_at_rest() -> Iterator[None]:
    """Within the block, SIGINT, SIGTERM, SIGHUP and SIGQUIT raise :class:`Interrupted` once (main thread only).

    Later signals are recorded and ignored: the glide to rest already goes as fast as the limits allow, and torque
    off mid-pose would let the arms drop. A SIGHUP that was ignored when the block began (``nohup``) stays ignored.
    Outside the main thread this is a no-op (signals are delivered to the main thread only).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old: dict[int, Any] = {}
    if _SIG.active == 0:
        _SIG.fired, _SIG.pending, _SIG.later = None, None, []
        for name in HANDLED_SIGNALS:
            sig = getattr(signal, name, None)
            if sig is None:
                continue
            prev = signal.getsignal(sig)
            if name == "SIGHUP" and prev == signal.SIG_IGN:
                continue
            old[sig] = prev
            signal.signal(sig, _on_signal)
    _SIG.active += 1
    try:
        yield
    finally:
        _SIG.active -= 1
        for sig, prev in old.items():
            signal.signal(sig, prev)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """A block that is atomic with respect to signals (main thread): one that arrives inside is raised at its end
    (a tick, so goal and limiter state never disagree; a shutdown, so the glide and torque off run to the end).
    Blocks nest; the outermost raises."""
    main = threading.current_thread() is threading.main_thread()
    if main:
        _SIG.critical += 1
    try:
        yield
    finally:
        if main:
            _SIG.critical -= 1
    if main:
        _raise_pending()
