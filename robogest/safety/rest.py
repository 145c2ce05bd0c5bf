"""Rest pinning: which frames of long silent periods target the rest pose, for a whole mask or one that grows.

A run of silent frames ``[a, b)`` lasting at least ``rest_after_s`` targets rest from ``a`` up to ``L``, the first
frame with ``k/fps ≥ b/fps − rest_leave_s`` (the robot may leave then, to be in place when speech resumes), or to
``b`` when the run reaches the end of the input. A stream sees ``b`` late: :func:`rest_decisions` tells how many
of the frames seen so far are decided (whatever follows), so an incremental stage never commits a frame whose
target could still change.
"""

from __future__ import annotations

import math

import numpy as np

from robogest.errors import InputError


def _runs(silent_mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and ends ``[a, b)`` of the silent runs of a ``(T,)`` bool mask."""
    m = np.asarray(silent_mask, dtype=bool)
    edges = np.diff(np.concatenate([[False], m, [False]]).astype(np.int8))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def long_silent_spans(silent_mask: np.ndarray, fps: float, rest_after_s: float) -> list[tuple[int, int]]:
    """Maximal runs ``[start, end)`` of silent frames lasting at least ``rest_after_s`` (``(end−start)/fps``).

    Parameters
    ----------
    silent_mask : ndarray [shape=(T,)], bool
    fps : float, frames/s
    rest_after_s : float, seconds
    """
    starts, ends = _runs(silent_mask)
    need = rest_after_s * fps - 1e-9
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True) if b - a >= need]


def rest_decisions(
    silent_mask: np.ndarray,
    fps: float,
    rest_after_s: float,
    rest_leave_s: float,
    *,
    final: bool = True,
    run_start: int | None = None,
) -> tuple[int, np.ndarray]:
    """Which frames of ``silent_mask`` target rest, and how many of them are decided.

    Parameters
    ----------
    silent_mask : ndarray [shape=(T,)], bool
        The frames not committed yet.
    fps : float, frames/s
    rest_after_s, rest_leave_s : float, seconds
    final : bool
        No frame follows these (a run reaching the end holds rest to it); False: more may follow.
    run_start : int or None
        Where a silent run going on at frame 0 began, counted from frame 0 (≤ 0): frames already committed.

    Returns
    -------
    n_decided : int
        Frames ``0..n_decided-1`` keep their decision whatever follows (all of them when ``final``).
    rest : ndarray [shape=(T,)], bool
        Frames whose target is rest (exact for the decided ones).
    """
    starts, ends = _runs(silent_mask)
    n_t = int(np.asarray(silent_mask).shape[0])
    rest = np.zeros(n_t, dtype=bool)
    decided = n_t
    need = rest_after_s * fps - 1e-9
    for a, b in zip(starts, ends, strict=True):
        a0 = run_start if a == 0 and run_start is not None else int(a)
        open_run = b == n_t and not final  # it may go on: its end, and so its leave frame, is not known yet
        if b - a0 < need:
            if open_run:
                decided = int(a)
            continue
        if open_run:  # long already: rest at least up to the leave frame its present length gives
            leave = max(a0, math.ceil(b - rest_leave_s * fps - 1e-9))
            decided = max(leave, 0)
        else:
            leave = b if b == n_t else max(a0, math.ceil(b - rest_leave_s * fps - 1e-9))
        rest[max(a0, 0) : max(leave, 0)] = True
    return decided, rest


def silent_rest_targets(
    q: np.ndarray,
    silent_mask: np.ndarray,
    rest_q: np.ndarray,
    fps: float,
    rest_after_s: float,
    rest_leave_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Replace the targets of long silent periods of a whole trajectory with the rest pose (module docstring).

    Parameters
    ----------
    q : ndarray [shape=(T, J)], radians
    silent_mask : ndarray [shape=(T,)], bool
    rest_q : ndarray [shape=(J,)], radians
    fps : float, frames/s
    rest_after_s, rest_leave_s : float, seconds

    Returns
    -------
    targets : ndarray [shape=(T, J)], radians
    hold_mask : ndarray [shape=(T,)], bool
        Frames whose target is rest.
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        raise InputError(f"q must have shape (T, J), got {q.shape}")
    silent_mask = np.asarray(silent_mask, dtype=bool)
    if silent_mask.shape != (q.shape[0],):
        raise InputError(f"silent mask has shape {silent_mask.shape}, expected ({q.shape[0]},) to match q")
    _, hold = rest_decisions(silent_mask, fps, rest_after_s, rest_leave_s)
    targets = q.copy()
    targets[hold] = rest_q
    return targets, hold
