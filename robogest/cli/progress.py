"""Progress of a long command as a ``(done, total) -> None`` callback.

On a terminal: a rich progress bar on stderr. When stderr is a pipe or a file (a log, ``2>&1 | tee``):
plain lines, ``robogest: LABEL: 40% (200/500)``, one per 10 % step and only once the command has run
for a second (short runs print nothing), each flushed at once; with ``eta`` (a video render) each line also says
how long the rest will take, from the rate since the first update. Otherwise (stderr replaced in-process,
as by test capture) nothing.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

#: Plain progress lines start only after this long, so quick runs stay quiet.
QUIET_FIRST_S = 1.0


def _is_real_file(stream: TextIO) -> bool:
    try:
        return stream.fileno() >= 0
    except (AttributeError, OSError, ValueError):
        return False


def progress_lines(
    label: str, stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic, eta: bool = False
) -> Callable[[float, float], None]:
    """A callback printing ``robogest: LABEL: P% (done/total)`` at each new 10 % step after ``QUIET_FIRST_S``;
    with ``eta``, followed by ``, about N s left`` once the work has advanced since the first update.

    Progress never stops the work it reports on: if the stream fails (a closed pipe), lines stop, the
    motion goes on.
    """
    start = clock()
    first: tuple[float, float] | None = None  # (time, done) of the first update: set-up before it is not the rate
    last_step = -1

    def update(done: float, total: float) -> None:
        nonlocal last_step, first
        now = clock()
        if first is None:
            first = (now, done)
        if not total or last_step > 10 or now - start < QUIET_FIRST_S:
            return
        step = min(10, int(10 * done // total))  # done/total may be seconds (floats): print whole percents
        left = _time_left_s(first, now, done, total) if eta else None
        if eta and done < total and (left is None or now - first[0] < QUIET_FIRST_S):
            return  # the first line waits for an estimate from a second of work
        if step > last_step:
            last_step = step
            note = "" if left is None else f", about {left:.0f} s left"
            try:
                print(f"robogest: {label}: {10 * step}% ({done}/{total}){note}", file=stream or sys.stderr, flush=True)
            except (OSError, ValueError):  # closed pipe or file: stop reporting, keep working
                last_step = 11

    return update


def _time_left_s(first: tuple[float, float], now: float, done: float, total: float) -> float | None:
    """Seconds until ``total`` at the rate since ``first`` (time, done); None before any progress or at the end."""
    t0, done0 = first
    if done <= done0 or now <= t0 or done >= total:
        return None
    return (now - t0) * (total - done) / (done - done0)


@contextmanager
def progress_bar(label: str, eta: bool = False) -> Iterator[Callable[[float, float], None]]:
    """A progress callback for ``label``: a rich bar with the time left on a terminal, else
    :func:`progress_lines` (with the time left if ``eta``)."""
    if not sys.stderr.isatty():
        yield progress_lines(label, eta=eta) if _is_real_file(sys.stderr) else (lambda done, total: None)
        return
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(), transient=True,
    ) as prog:  # fmt: skip
        task = prog.add_task(label, total=None)

        def update(done: float, total: float) -> None:
            prog.update(task, completed=done, total=total)

        yield update
