"""One safety stage for a whole trajectory and for a stream: :class:`SafetyStage`.

The same stages run in the same order whether the motion comes whole (:func:`~robogest.safety.apply_safety`
calls :meth:`SafetyStage.extend` once with ``last=True``, then :meth:`SafetyStage.finish`) or in chunks (the
streaming planner calls it once per plan): position clamp with the margin → Gaussian smoothing → rate limiter →
rest pinning in long silent periods → with ``preview``, the least-squares fit within the limits
(:func:`~robogest.safety.fit.fit_within_limits`) → :func:`~robogest.safety.stages.track`, continuing from the
position and step the previous chunk ended with.

Frames are committed only when nothing that follows can change their targets: the smoothing kernel needs
``kernel // 2`` frames after each frame, and a frame in a silent run waits until the run is known to be long
(or to have ended) and the frame to lie before the run's leave time. Held frames come out with a later chunk or
:meth:`SafetyStage.finish`. So any chunking gives a trajectory inside the limits that rests in every long silent
period; a single chunk gives exactly what the whole-trajectory stages give (bit for bit).

A refusal (NaN/inf in the input, or a chunk the tracker cannot continue within the limits) raises
:class:`~robogest.errors.SafetyError` naming the frame and joint; nothing of that chunk is returned.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from robogest.errors import InputError, SafetyError
from robogest.safety.fit import fit_within_limits
from robogest.safety.limits import JointLimits, SafetyConfig, _joint_list
from robogest.safety.rest import rest_decisions
from robogest.safety.stages import (
    check_limits,
    clamp_positions,
    continuation_bounds,
    gaussian_kernel,
    settle_tail,
    track_run,
)

_CHANGED_RAD = 1e-6  # a stage "changed" a sample if it moved it by more than this


def check_finite(q: np.ndarray, limits: JointLimits, fps: float, frame0: int = 0) -> None:
    """Raise :class:`SafetyError` naming frames (numbered from ``frame0``) and joints where ``q (T, J)`` is NaN/inf."""
    bad = ~np.isfinite(q)
    if bad.any():
        frames = np.flatnonzero(bad.any(axis=1)) + frame0
        joints = np.flatnonzero(bad.any(axis=0))
        shown = ", ".join(f"{f} (t={f / fps:.3f} s)" for f in frames[:5]) + (" …" if frames.size > 5 else "")
        raise SafetyError(
            f"safety: motion contains NaN/inf at {int(bad.sum())} samples: frames {shown}; "
            f"joints {_joint_list(joints, limits.names)}. The generator output is invalid; nothing was commanded."
        )


def checked_q0(q0: np.ndarray, limits: JointLimits) -> np.ndarray:
    """``q0 (J,)`` radians as floats, or :class:`SafetyError`/:class:`InputError` naming the bad joints."""
    n_j = limits.n_joints
    q0 = np.asarray(q0, dtype=float)
    if q0.shape != (n_j,):
        raise InputError(f"safety: q0 has shape {q0.shape}, expected ({n_j},)")
    bad = np.flatnonzero(~np.isfinite(q0))
    if bad.size:
        raise SafetyError(f"safety: current pose q0 is NaN/inf for joints {_joint_list(bad, limits.names)}")
    bad = np.flatnonzero((q0 < limits.q_min_rad) | (q0 > limits.q_max_rad))
    if bad.size:
        raise SafetyError(
            f"safety: current pose q0 is outside the joint limits for joints {_joint_list(bad, limits.names)}; "
            "move the robot inside its limits (or fix the limits) before commanding it"
        )
    return q0


@dataclass
class StageCounts:
    """Input samples ``(frame, joint)`` each stage moved by more than 1e-6 rad, over the frames committed."""

    clamp: int = 0
    smooth: int = 0
    velocity: int = 0
    track: int = 0
    any_limit: int = 0  #: moved by the clamp, the rate limiter or the tracker (outside rest targets)
    samples: int = 0


@dataclass
class _Pending:
    """Input received but not committed: raw and clamped ``(P, J)`` radians, silent and pinned ``(P,)`` bool."""

    raw: np.ndarray
    clamped: np.ndarray
    silent: np.ndarray
    pinned: np.ndarray

    def take(self, n: int) -> None:
        self.raw, self.clamped = self.raw[n:], self.clamped[n:]
        self.silent, self.pinned = self.silent[n:], self.pinned[n:]


class SafetyStage:
    """Makes a motion safe chunk by chunk (module docstring); batch and stream share it.

    Parameters
    ----------
    limits : JointLimits
    fps : float, frames/s
    config : SafetyConfig, optional
    q0 : ndarray [shape=(J,)], radians, optional
        The robot's pose at the first frame, standing still; default rest (or the first smoothed frame when
        ``config.start_from_rest`` is False).
    """

    def __init__(
        self, limits: JointLimits, fps: float, config: SafetyConfig | None = None, q0: np.ndarray | None = None
    ) -> None:
        if isinstance(fps, bool) or not (isinstance(fps, numbers.Real) and np.isfinite(fps) and fps > 0):
            raise InputError(f"safety: fps must be a finite number > 0, got {fps!r}")
        self.limits: JointLimits = limits
        self.fps: float = float(fps)
        self.config: SafetyConfig = SafetyConfig() if config is None else config
        self.dt_s: float = 1.0 / self.fps
        self._kernel: np.ndarray = gaussian_kernel(self.config.smooth_kernel, self.config.smooth_sigma)  # (k,) weights
        self._q0: np.ndarray | None = None if q0 is None else checked_q0(q0, limits)
        n_j: int = limits.n_joints
        empty = np.empty((0, n_j))
        self._pending: _Pending = _Pending(empty, empty, np.empty(0, bool), np.empty(0, bool))
        self._history: np.ndarray | None = None  # (r, J) clamped frames before the pending ones
        self._rate_in: np.ndarray | None = None  # (J,) last smoothed frame into the rate limiter
        self._rate_out: np.ndarray | None = None  # (J,) its output there
        self._rate_exact: bool = True  # the rate limiter has passed its input through unchanged so far
        self._run_start: int | None = None  # frame where the silent run through the last committed frame began
        self._last: np.ndarray | None = None  # (≤2, J) the last frames committed
        self._step: np.ndarray = np.zeros(n_j)  # the tracker's last step, radians per frame
        self._bounds: tuple[np.ndarray, np.ndarray, np.ndarray | None] = continuation_bounds(
            limits, self.dt_s, limits.rest_q_rad, self.config.margin_rad
        )
        self.n_frames: int = 0  #: frames committed so far (input frames; the start of the next chunk)
        self.n_input: int = 0  #: frames received so far
        self.counts: StageCounts = StageCounts()
        self.rest_target: np.ndarray = np.empty(0, bool)  #: ``(T',)`` the last chunk's frames whose target was rest
        self._ended: bool = False

    # --- the two calls -----------------------------------------------------------------------------------------
    def extend(
        self,
        q_rad: np.ndarray,
        silent: np.ndarray | None = None,
        *,
        pinned: np.ndarray | None = None,
        last: bool = False,
    ) -> np.ndarray:
        """Commit what the frames so far decide: safe commands ``(T', J)`` radians, continuing the previous ones.

        Parameters
        ----------
        q_rad : ndarray [shape=(T, J)], radians
            The next frames of the retargeted motion.
        silent : ndarray [shape=(T,)], bool, optional
            Frames inside silent periods of any length (this stage picks the long ones).
        pinned : ndarray [shape=(T,)], bool, optional
            Frames whose target is rest whatever the silence says (e.g. where the generator rests).
        last : bool
            No frames follow: commit every frame (a run of silence reaching the end holds rest to it).

        Returns
        -------
        ndarray [shape=(T', J)], radians
            ``T' ≤`` the frames held plus ``T``; the first chunk's frame 0 is ``q0``.
        """
        if self._ended:
            raise InputError("safety: extend() after the last chunk; make a new SafetyStage for a new motion")
        n_j = self.limits.n_joints
        q = np.asarray(q_rad, dtype=float)
        if q.ndim != 2 or q.shape[1] != n_j:
            raise InputError(f"safety: motion has shape {q.shape}, expected (T, {n_j}) for this robot's joints")
        n_t = q.shape[0]
        sil, pin = (self._mask(m, n_t, name) for m, name in ((silent, "silent"), (pinned, "pinned")))
        check_finite(q, self.limits, self.fps, self.n_input)
        pend = self._pending
        clamped = clamp_positions(q, self.limits, self.config.margin_rad)
        pend.raw, pend.clamped = np.vstack([pend.raw, q]), np.vstack([pend.clamped, clamped])
        pend.silent, pend.pinned = np.r_[pend.silent, sil], np.r_[pend.pinned, pin]
        self.n_input += n_t
        self._ended = last
        cfg = self.config
        run_start = None if self._run_start is None else self._run_start - self.n_frames
        n, rest = rest_decisions(
            pend.silent, self.fps, cfg.rest_after_s, cfg.rest_leave_s, final=last, run_start=run_start
        )
        if not last:
            n = min(n, pend.silent.size - cfg.smooth_kernel // 2)  # the smoothing looks this far ahead
        if n <= 0:
            self.rest_target = np.empty(0, bool)
            return np.empty((0, n_j))
        return self._commit(n, rest[:n] | pend.pinned[:n], last)

    def finish(self) -> np.ndarray:
        """The frames still held, then the way to rest: ``(N, J)`` radians ending at rest with zero velocity."""
        held = self.extend(np.empty((0, self.limits.n_joints)), last=True) if not self._ended else None
        self._ended = True
        if self._last is None:  # nothing committed (an empty motion): the start pose is the first command
            q0 = self._start_pose(None)
            self._last, self._step = q0[None], np.zeros_like(q0)
            self._bounds = continuation_bounds(self.limits, self.dt_s, q0, self.config.margin_rad)
            self.n_frames = 1
            first = q0[None]
        else:
            first = np.empty((0, self.limits.n_joints))
        last = self._last
        tail = settle_tail(last, last[-1].copy(), self._step, self.limits, self.dt_s, self.config.margin_rad)
        lo_ok, hi_ok, _ = self._bounds
        d0 = None if last.shape[0] == 1 else last[-1] - last[-2]
        check_limits(np.vstack([last[-1:], tail]), self.limits, self.dt_s, lo_ok, hi_ok, d0, self.n_frames - 1)
        parts = [first, tail] if held is None else [held, first, tail]
        return np.vstack(parts)

    def resume(self, q_rad: np.ndarray, step_rad: np.ndarray, frame: int) -> None:
        """Continue after frame ``frame``, already commanded at ``q_rad (J,)`` moving ``step_rad (J,)`` per frame:
        the next :meth:`extend` gives frames ``frame + 1...`` (a streamed plan replacing provisional frames).
        Frames held from before are dropped, and smoothing and silent runs start afresh there."""
        q = np.asarray(q_rad, dtype=float)
        step = np.asarray(step_rad, dtype=float)
        check_finite(np.vstack([q, step]), self.limits, self.fps, frame)
        empty = np.empty((0, self.limits.n_joints))
        self._pending = _Pending(empty, empty, np.empty(0, bool), np.empty(0, bool))
        self._history, self._run_start, self._ended = None, None, False
        self._rate_in, self._rate_out, self._rate_exact = q.copy(), q.copy(), False
        self._last, self._step = np.vstack([q - step, q]), step.copy()
        self._bounds = continuation_bounds(self.limits, self.dt_s, q, self.config.margin_rad, step)
        self.n_frames = self.n_input = frame + 1

    # --- the stages, on the frames being committed -------------------------------------------------------------
    def _commit(self, n: int, rest: np.ndarray, last: bool) -> np.ndarray:
        """Run the stages on the first ``n`` pending frames (``rest (n,)``: their rest targets) and commit them."""
        pend, lim = self._pending, self.limits
        smoothed = self._smooth(n)
        rated = self._rate_limit(smoothed)
        src = smoothed if self.config.preview else rated  # the fit keeps the velocity limit itself, without lag
        targets = src.copy()
        targets[rest] = lim.rest_q_rad
        out = self._track(targets, rest, rated)
        self._count(pend.raw[:n], pend.clamped[:n], smoothed, rated, src, out, rest)
        r = self.config.smooth_kernel // 2
        if r:
            self._history = np.vstack([self._history_or_edge(), pend.clamped[:n]])[-r:]
        sil = pend.silent[:n]
        if not sil[-1]:
            self._run_start = None
        elif sil.all() and self._run_start is not None:
            pass  # the run that began before these frames goes on
        else:
            self._run_start = self.n_frames + (int(np.flatnonzero(~sil)[-1]) + 1 if (~sil).any() else 0)
        pend.take(n)
        self.n_frames += n
        self.rest_target = rest
        return out

    def _count(
        self,
        raw: np.ndarray,
        clamped: np.ndarray,
        smoothed: np.ndarray,
        rated: np.ndarray,
        src: np.ndarray,
        out: np.ndarray,
        rest: np.ndarray,
    ) -> None:
        """Add the samples each stage changed in these ``(n, J)`` frames to :attr:`counts`."""
        c = self.counts
        c_clamp = np.abs(clamped - raw) > _CHANGED_RAD
        c_vel = np.abs(rated - smoothed) > _CHANGED_RAD
        c_track = (np.abs(out - src) > _CHANGED_RAD) & ~rest[:, None]
        c.clamp += int(c_clamp.sum())
        c.smooth += int((np.abs(smoothed - clamped) > _CHANGED_RAD).sum())
        c.velocity += int(c_vel.sum())
        c.track += int(c_track.sum())
        c.any_limit += int((c_clamp | c_vel | c_track).sum())
        c.samples += out.size

    def _history_or_edge(self) -> np.ndarray:
        """``(r, J)`` clamped frames before the pending ones; at the start, the first one repeated (edge padding)."""
        if self._history is not None:
            return self._history
        return np.repeat(self._pending.clamped[:1], self.config.smooth_kernel // 2, axis=0)

    def _smooth(self, n: int) -> np.ndarray:
        """Gaussian smoothing of the first ``n`` pending frames (as :func:`~robogest.safety.stages.smooth` does for
        a whole trajectory: edges padded with the end frames)."""
        c = self._pending.clamped
        r = self.config.smooth_kernel // 2
        if r == 0:
            return np.array(c[:n], dtype=float)
        ahead = c[n : n + r]
        if ahead.shape[0] < r:  # the end of the motion: pad with its last frame
            ahead = np.vstack([ahead, np.repeat(c[-1:], r - ahead.shape[0], axis=0)])
        padded = np.vstack([self._history_or_edge(), c[:n], ahead])
        out = np.zeros((n, c.shape[1]))
        for i, wi in enumerate(self._kernel):
            out += wi * padded[i : i + n]
        return out

    def _rate_limit(self, q: np.ndarray) -> np.ndarray:
        """Rate limiter (:func:`~robogest.safety.stages.clamp_velocity`) continued across chunks, ``(n, J)``."""
        vstep = self.limits.v_max_rad_s * self.dt_s
        x = q if self._rate_in is None else np.vstack([self._rate_in[None], q])
        out = q.copy()
        if not (self._rate_exact and np.all(np.abs(np.diff(x, axis=0)) <= vstep)):  # else keep the input bit-exact
            self._rate_exact = False
            p = out[0].copy() if self._rate_out is None else self._rate_out.copy()
            neg = -vstep
            for k in range(1 if self._rate_out is None else 0, q.shape[0]):
                p = p + np.minimum(np.maximum(q[k] - p, neg), vstep)
                out[k] = p
        self._rate_in, self._rate_out = q[-1].copy(), out[-1].copy()
        return np.asarray(out, dtype=float)

    def _start_pose(self, rated: np.ndarray | None) -> np.ndarray:
        if self._q0 is not None:
            return np.array(self._q0, dtype=float)
        if self.config.start_from_rest or rated is None:
            return np.array(self.limits.rest_q_rad, dtype=float)
        return np.array(rated[0], dtype=float)

    def _track(self, targets: np.ndarray, rest: np.ndarray, rated: np.ndarray) -> np.ndarray:
        """Fit (with ``preview``) and track ``targets (n, J)`` from the last committed frame, or from ``q0``."""
        lim, dt, margin = self.limits, self.dt_s, self.config.margin_rad
        if self._last is None:  # the first chunk: its frame 0 is the start pose, standing still
            q0, x, mask, step0 = self._start_pose(rated), targets, rest, None
            frame0, d0 = 0, None
            self._bounds = continuation_bounds(lim, dt, q0, margin)
        else:
            q0 = self._last[-1]
            x, mask, step0 = np.vstack([q0[None], targets]), np.r_[False, rest], self._step
            frame0, d0 = self.n_frames - 1, (q0 - self._last[-2]) if self._last.shape[0] > 1 else None
        if self.config.preview and x.shape[0] > 1:
            x = fit_within_limits(x, lim, dt, q0, margin_rad=margin, rest_mask=mask, step0=step0)
        out, _, s = track_run(x, lim, dt, q0, margin_rad=margin, rest_mask=mask, step0=step0)
        if step0 is not None:  # a continuation: the bounds its braking may use
            self._bounds = continuation_bounds(lim, dt, q0, margin, step0)
        lo_ok, hi_ok, _ = self._bounds
        check_limits(out, lim, dt, lo_ok, hi_ok, d0, frame0)
        self._last, self._step = np.vstack([self._last, out])[-2:] if self._last is not None else out[-2:], s
        return out if step0 is None else out[1:]

    def _mask(self, m: np.ndarray | None, n_t: int, name: str) -> np.ndarray:
        if m is None:
            return np.zeros(n_t, dtype=bool)
        m = np.asarray(m)
        if m.shape != (n_t,):
            raise InputError(f"safety: {name} mask has shape {m.shape}, expected ({n_t},) to match the motion")
        return m.astype(bool)
