"""Progress of a long command as a ``(done, total) -> None`` callback.

On a terminal: a rich progress bar on stderr. When stderr is a pipe or a file (a log, ``2>&1 | tee``):
plain lines, ``robogest: LABEL: 40% (200/500)``, one per 10 % step and only once the command has run
for a second (short runs print nothing), each flushed at once. Otherwise (stderr replaced in-process,
as by test capture) nothing.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

#: Plain progress lines start only after this long, so quick runs stay quiet.
QUIET_FIRST_S = 1.0


def _is_real_file(stream: object) -> bool:
    try:
        return stream.fileno() >= 0  # type: ignore[attr-defined]
    except (AttributeError, OSError, ValueError):
        return False


def progress_lines(label: str, stream=None, clock: Callable[[], float] = time.monotonic) -> Callable[[int, int], None]:
    """A callback printing ``robogest: LABEL: P% (done/total)`` at each new 10 % step after ``QUIET_FIRST_S``.

    Progress never stops the work it reports on: if the stream fails (a closed pipe), lines stop, the
    motion goes on.
    """
    start = clock()
    last_step = -1

    def update(done: int, total: int) -> None:
        nonlocal last_step
        if not total or last_step > 10 or clock() - start < QUIET_FIRST_S:
            return
        step = min(10, int(10 * done // total))  # done/total may be seconds (floats): print whole percents
        if step > last_step:
            last_step = step
            try:
                print(f"robogest: {label}: {10 * step}% ({done}/{total})", file=stream or sys.stderr, flush=True)
            except (OSError, ValueError):  # closed pipe or file: stop reporting, keep working
                last_step = 11

    return update


@contextmanager
def progress_bar(label: str) -> Iterator[Callable[[int, int], None]]:
    if not sys.stderr.isatty():
        yield progress_lines(label) if _is_real_file(sys.stderr) else (lambda done, total: None)
        return
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(), transient=True,
    ) as prog:  # fmt: skip
        task = prog.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            prog.update(task, completed=done, total=total)

        yield update
