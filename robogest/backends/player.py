"""Real-time trajectory player: streams a :class:`Trajectory` to any :class:`Backend` at a fixed rate.

The clock is ``time.monotonic`` with an absolute schedule (tick ``k`` is due at ``t0 + k / rate``),
so one slow tick does not shift the rest; ticks that fall more than half a period behind are
counted as late and, when a whole period was lost, skipped rather than bunched. Simulated backends
(``realtime = False``) are advanced by ``1 / rate`` per tick instead of waiting.

Safety: the trajectory must match the robot definition (joints, limits, rest pose; limits come from
the robot, never the file); commands are clipped to the robot's limits and each step to its velocity
limit from the last goal sent (a late tick does not make a jump); the robot ramps from wherever it is to
the first pose and back to rest with a minimum-jerk profile timed so that neither the velocity nor
the acceleration limit is exceeded; the backend's guard refuses any goal that still breaks a limit;
``backend.shutdown`` (rest, then torque off) always runs in a ``finally``, and SIGTERM is turned into an
exception so it takes the same path as Ctrl-C.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robogest.backends.base import Backend
from robogest.errors import BackendError, RobogestError
from robogest.trajectory.types import Trajectory, check_matches

_MJ_VEL, _MJ_ACC = 1.875, 5.7735  # peak |s'| and |s''| of the minimum-jerk blend on [0, 1]


def ramp_duration(q0: np.ndarray, q1: np.ndarray, v_max: np.ndarray, a_max: np.ndarray, margin: float = 1.1) -> float:
    """Seconds a minimum-jerk move ``q0 -> q1`` needs so every joint stays within ``v_max`` and ``a_max``.

    Parameters
    ----------
    q0, q1 : ndarray [shape=(J,)], radians
    v_max : ndarray [shape=(J,)], rad/s
    a_max : ndarray [shape=(J,)], rad/s²
    """
    d = np.abs(np.asarray(q1, float) - np.asarray(q0, float))
    if not d.size or float(d.max()) == 0.0:
        return 0.0
    t = np.maximum(_MJ_VEL * d / v_max, np.sqrt(_MJ_ACC * d / a_max))
    return float(t.max() * margin)


def ramp_sample(q0: np.ndarray, q1: np.ndarray, t_s: float, duration_s: float) -> np.ndarray:
    """Minimum-jerk blend ``(J,)`` at ``t_s`` (held at ``q1`` after ``duration_s``)."""
    if duration_s <= 0 or t_s >= duration_s:
        return np.asarray(q1, float).copy()
    x = max(0.0, t_s / duration_s)
    s = x**3 * (10 - 15 * x + 6 * x * x)
    return (1 - s) * np.asarray(q0, float) + s * np.asarray(q1, float)


@dataclass
class PlaybackReport:
    """How a playback went. Periods are wall-clock intervals between tick starts, milliseconds.

    ``jitter_ms`` is the mean absolute deviation of the period from the nominal ``1000 / rate_hz``;
    ``late_ticks`` counts ticks that started more than half a period after their slot. ``retries``
    counts re-sent transactions and re-read servos on a serial bus; ``missed_reads`` counts present
    positions that got no valid reply within their tick (the last known value was used instead).
    """

    n_ticks: int = 0
    p50_period_ms: float = 0.0
    p99_period_ms: float = 0.0
    jitter_ms: float = 0.0
    late_ticks: int = 0
    duration_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    ramp_in_s: float = 0.0
    retries: int = 0
    missed_reads: int = 0
    completed: bool = False
    audio: bool = False


class Terminated(SystemExit):
    """SIGTERM arrived: a SystemExit (status 143), so ``finally`` blocks run and ``except Exception`` ignores it."""


@contextlib.contextmanager
def sigterm_as_exception() -> Iterator[None]:
    """Turn the first SIGTERM into :class:`Terminated` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    fired = False

    def handler(signum: int, frame: Any) -> None:
        nonlocal fired
        if not fired:  # a second SIGTERM must not interrupt the shutdown the first one started
            fired = True
            raise Terminated(128 + signum)

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


class _Audio:
    """Speech playback through ``sounddevice`` when it and an output device exist; otherwise nothing."""

    def __init__(self, audio: np.ndarray | None, sr: int) -> None:
        self.sd: Any = None
        self.audio = audio
        self.sr = sr
        if audio is None or len(audio) == 0:
            return
        try:
            import sounddevice as sd

            sd.query_devices(kind="output")
            self.sd = sd
        except Exception:  # not installed, no PortAudio, or no output device: play silently
            self.sd = None

    def start(self) -> bool:
        if self.sd is None:
            return False
        try:
            self.sd.play(np.asarray(self.audio, dtype=np.float32), self.sr, blocking=False)
            return True
        except Exception:
            self.sd = None
            return False

    def stop(self) -> None:
        if self.sd is not None:
            with contextlib.suppress(Exception):
                self.sd.stop()


def play(
    trajectory: Trajectory,
    backend: Backend,
    *,
    rate_hz: float = 50.0,
    audio: np.ndarray | None = None,
    audio_sr: int = 16000,
    progress: Callable[[float, float], None] | None = None,
    time_scale: float = 1.0,
    read_back: bool = True,
) -> PlaybackReport:
    """Play ``trajectory`` on ``backend`` and leave the robot at rest with torque off.

    Parameters
    ----------
    trajectory : Trajectory
        Commands ``(T, J)`` in radians with the limits they satisfy.
    backend : Backend
        Connected here unless it reports ``is_connected``; always shut down before returning.
    rate_hz : float
        Control rate.
    audio : ndarray [shape=(N,)], optional
        Speech samples started together with the first trajectory sample (not the ramp-in).
    audio_sr : int
        Sample rate of ``audio``, Hz.
    progress : callable (t_s, duration_s), optional
        Called every tick.
    time_scale : float
        Trajectory seconds per wall second (tests use > 1 to run faster than real time; audio is
        skipped when it is not 1). Each goal is still limited to the robot's velocity limit per tick
        (``1 / rate_hz``), so a scaled-up trajectory is followed only as fast as that allows.
    read_back : bool
        Read present positions every tick (detects lost servos and hardware errors within one tick).

    Returns
    -------
    PlaybackReport

    Raises
    ------
    InputError
        The trajectory does not match ``backend.robot`` (nothing moved).
    SafetyError
        The backend refused a goal; the robot was sent to rest and torque turned off.
    BackendError
        A servo or the port failed; the motion was stopped, torque turned off, and the partial
        report is attached as ``error.report``.
    """
    if rate_hz <= 0 or time_scale <= 0:
        raise ValueError("rate_hz and time_scale must be positive")
    robot = backend.robot
    check_matches(trajectory, robot)
    period = 1.0 / rate_hz
    report = PlaybackReport()
    lo, hi = robot.q_min_rad, robot.q_max_rad
    step_max = robot.v_max_rad_s * period
    starts: list[float] = []
    sound = _Audio(audio if time_scale == 1.0 else None, audio_sr)
    wall0 = time.monotonic()

    def run_phase(sample: Callable[[float], np.ndarray], length_s: float, on_start: Callable[[], None] | None) -> None:
        """Stream ``sample(t)`` for ``t`` in trajectory seconds ``[0, length_s]``."""
        if on_start:
            on_start()
        t0 = time.monotonic()
        k = 0
        while True:
            t_traj = min(k * period * time_scale, length_s)
            if backend.realtime:
                due = t0 + k * period
                now = time.monotonic()
                if now < due:
                    time.sleep(due - now)
                    now = time.monotonic()
                if now - due > 0.5 * period:
                    report.late_ticks += 1
                starts.append(now)
            q = np.clip(backend.shape_target(sample(t_traj), robot.rest_q_rad), lo, hi)
            last = backend.last_goal_rad
            if last is not None:  # after a late tick, catch up at the velocity limit instead of jumping
                q = last + np.clip(q - last, -step_max, step_max)
            backend.write_goal(q, source="trajectory playback")
            if read_back:
                backend.read_positions()
            report.n_ticks += 1
            if progress:
                progress(t_traj, length_s)
            if t_traj >= length_s:
                return
            if not backend.realtime:
                backend.advance(period)
                k += 1
            else:
                behind = int((time.monotonic() - t0) / period)
                k = max(k + 1, behind)  # skip slots already lost instead of bunching ticks

    with sigterm_as_exception():
        try:
            backend.set_control_rate(rate_hz)  # the guard's velocity bound; serial backends' lost-servo ticks
            if not getattr(backend, "is_connected", False):
                backend.connect()
            q_now = np.clip(backend.read_positions(), lo, hi)
            backend.write_goal(q_now, source="present pose at start")  # hold, so enabling torque does not jump
            backend.set_torque(True)
            q_first = np.clip(trajectory.sample(0.0), lo, hi)
            ramp_in = ramp_duration(q_now, q_first, robot.v_max_rad_s, robot.a_max_rad_s2)
            report.ramp_in_s = ramp_in
            if ramp_in > 0:
                run_phase(lambda t: ramp_sample(q_now, q_first, t, ramp_in), ramp_in, None)

            def start_audio() -> None:
                report.audio = sound.start()

            run_phase(trajectory.sample, trajectory.duration_s, start_audio)
            q_last = np.clip(backend.last_goal_rad, lo, hi)  # where the robot was really sent, not the file
            rest = np.clip(robot.rest_q_rad, lo, hi)
            ramp_out = ramp_duration(q_last, rest, robot.v_max_rad_s, robot.a_max_rad_s2)
            run_phase(lambda t: ramp_sample(q_last, rest, t, ramp_out), ramp_out, None)
            _settle(backend, rest, period)
            report.completed = True
        except RobogestError as e:
            report.errors.append(str(e))
            e.report = report  # type: ignore[attr-defined]
            raise
        finally:
            sound.stop()
            try:
                backend.shutdown()
            finally:
                _finish(report, backend, starts, period, wall0)
    return report


def _settle(backend: Backend, rest: np.ndarray, period: float, tol_rad: float = 0.02, timeout_s: float = 0.5) -> None:
    """Hold rest until the joints get there (servos lag their goal), so torque goes off at rest."""
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / period) + 1):
        if np.max(np.abs(backend.read_positions() - rest)) <= tol_rad or time.monotonic() > deadline:
            return
        if backend.realtime:
            time.sleep(period)
        else:
            backend.advance(period)


def _finish(report: PlaybackReport, backend: Backend, starts: list[float], period: float, wall0: float) -> None:
    report.duration_s = time.monotonic() - wall0
    report.retries = int(getattr(backend, "retry_count", 0))
    report.missed_reads = int(getattr(backend, "missed_reads", 0))
    events = list(getattr(backend, "events", []))
    if events:
        shown = events[:20]
        report.errors.extend(shown)
        if len(events) > len(shown):
            report.errors.append(f"... and {len(events) - len(shown)} more bus events")
    if len(starts) >= 2:
        p = np.diff(np.asarray(starts)) * 1000.0
        report.p50_period_ms = float(np.percentile(p, 50))
        report.p99_period_ms = float(np.percentile(p, 99))
        report.jitter_ms = float(np.mean(np.abs(p - period * 1000.0)))


__all__ = ["BackendError", "PlaybackReport", "Terminated", "play", "ramp_duration", "ramp_sample"]
