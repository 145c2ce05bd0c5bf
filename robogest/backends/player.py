"""Trajectory player: plays a :class:`Trajectory` on any :class:`Backend` through the control loop.

There is one player: :func:`play` is a thin use of :class:`~robogest.backends.control.ControlLoop` (the
persistent loop the live session also uses, in ``robogest/backends/control.py``): start (hold the present
pose, torque on), play the trajectory, close (glide to rest, torque off). Every goal passes the loop's online
limiter, so position, velocity, acceleration and jerk limits hold at ``rate_hz`` whatever rate the trajectory
was made at. The clock is ``time.monotonic`` with an absolute schedule; a late tick advances the target time
while the goal still moves only one limited step from the last goal sent. Simulated backends
(``realtime = False``) are advanced by ``1 / rate`` per tick instead of waiting.

SIGINT, SIGTERM, SIGHUP and SIGQUIT raise :class:`~robogest.backends.signals.Interrupted` (a KeyboardInterrupt) after
the robot has glided to rest and torque is off; a second signal does not cut the glide short.
The trajectory must match the robot definition (joints, limits, rest pose; limits come from the robot, never
the file), and the backend's own guard refuses any goal that still breaks a limit.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from robogest.backends.base import Backend
from robogest.backends.control import ControlLoop
from robogest.backends.signals import Interrupted, signals_end_at_rest
from robogest.errors import BackendError, RobogestError
from robogest.media.audio import AudioOut, open_output
from robogest.trajectory.types import Trajectory, check_matches


@dataclass
class PlaybackReport:
    """How a playback went. Periods are wall-clock intervals between tick starts, milliseconds.

    ``jitter_ms`` is the mean absolute deviation of the period from the nominal ``1000 / rate_hz``;
    ``late_ticks`` counts ticks that started more than half a period after their slot; ``skipped_slots`` the
    whole periods lost to late ticks (the target time moved on; the goal still moved one limited step). ``retries``
    counts re-sent transactions and re-read servos on a serial bus; ``missed_reads`` counts present
    positions that got no valid reply within their tick (the last known value was used instead).
    """

    n_ticks: int = 0
    p50_period_ms: float = 0.0
    p99_period_ms: float = 0.0
    jitter_ms: float = 0.0
    late_ticks: int = 0
    skipped_slots: int = 0
    duration_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    ramp_in_s: float = 0.0
    retries: int = 0
    missed_reads: int = 0
    completed: bool = False
    audio: bool = False


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
    on_start: Callable[[float], None] | None = None,
) -> PlaybackReport:
    """Play ``trajectory`` on ``backend`` and leave the robot at rest with torque off.

    Parameters
    ----------
    trajectory : Trajectory
        Commands ``(T, J)`` in radians, joints in the robot's order; the limits applied are the robot's
        (``backend.robot``), not the file's.
    backend : Backend
        Connected here unless it reports ``is_connected``; always shut down before returning.
    rate_hz : float
        Control rate, Hz (any rate: the online limiter keeps every limit at this rate).
    audio : ndarray [shape=(N,)], optional
        Speech samples started together with the first trajectory sample (after any glide to its first pose).
    audio_sr : int
        Sample rate of ``audio``, Hz.
    progress : callable (t_s, duration_s), optional
        Called every tick while the trajectory plays.
    time_scale : float
        Trajectory seconds per wall second (tests use > 1 to run faster than real time; audio is
        skipped when it is not 1). Every goal still keeps the robot's limits at ``rate_hz``, so a sped-up
        trajectory is followed only as fast as they allow.
    read_back : bool
        Read present positions every tick (detects lost servos and hardware errors within one tick).
    on_start : callable (loop_s), optional
        Called when trajectory time 0 is reached, with the loop time (seconds since the loop started).

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
    Interrupted
        SIGINT/SIGTERM/SIGHUP/SIGQUIT; its ``outcome`` says whether the robot reached rest.
    """
    check_matches(trajectory, backend.robot)  # before anything moves
    report = PlaybackReport()
    sound = _sound(audio, audio_sr) if time_scale == 1.0 else None
    wall0 = time.monotonic()
    loop = ControlLoop(backend, rate_hz, threaded=False, read_back=read_back, time_scale=time_scale)
    with signals_end_at_rest():
        interrupted: BaseException | None = None
        try:
            _run(loop, trajectory, report, sound, progress, on_start)
        except RobogestError as e:
            report.errors.append(str(e))
            e.report = report  # type: ignore[attr-defined]
            raise
        except KeyboardInterrupt as e:
            interrupted = e
            raise
        finally:
            late = _end(report, backend, loop, wall0, sound, interrupted)
            if late is not None and interrupted is None and report.completed:
                raise late  # the play itself had ended: the signal is what the caller must hear of
    return report


def _run(
    loop: ControlLoop,
    trajectory: Trajectory,
    report: PlaybackReport,
    sound: AudioOut | None,
    progress: Callable[[float, float], None] | None,
    on_start: Callable[[float], None] | None,
) -> None:
    """Start the loop (present pose held, torque on) and play ``trajectory`` to its end; the speech starts with
    trajectory time 0 (after any glide to the first pose)."""
    loop.start()
    handle = loop.play(trajectory)
    handle.progress = progress

    def started() -> None:
        report.ramp_in_s = handle.events["started"].loop_s
        report.audio = sound is not None and sound.start()
        if on_start is not None:
            on_start(report.ramp_in_s)

    handle.on_start = started
    handle.wait()
    report.completed = True


def _sound(audio: np.ndarray | None, audio_sr: int) -> AudioOut | None:
    """The speech output with ``audio`` queued and its stream opened (outside the control tick that starts it);
    None without audio or without an output device."""
    sd = open_output()[0] if audio is not None and len(audio) else None
    if sd is None or audio is None:
        return None
    sound = AudioOut(sd, audio_sr)
    sound.write(audio)
    sound.finish()
    sound.open()
    return sound


def _end(
    report: PlaybackReport,
    backend: Backend,
    loop: ControlLoop,
    wall0: float,
    sound: AudioOut | None,
    interrupted: BaseException | None,
) -> Interrupted | None:
    """Silence, the glide to rest and torque off (``loop.close``), the report filled in; each interruption told
    where the robot ended. Returns an :class:`Interrupted` that arrived during the glide (raised once at rest)."""
    if sound is not None:
        sound.stop()
    late: Interrupted | None = None
    try:
        problem = loop.close()
    except Interrupted as e:  # arrived during the glide to rest: raised once at rest with torque off
        problem, late = loop.rest_problem, e
    finally:
        _finish(report, backend, loop, wall0)
    for it in (interrupted, late):
        if isinstance(it, Interrupted):
            it.outcome = (
                f"the robot {problem}; torque off attempted" if problem else "the robot went to rest and torque is off"
            )
    return late


def _finish(report: PlaybackReport, backend: Backend, loop: ControlLoop, wall0: float) -> None:
    report.duration_s = time.monotonic() - wall0
    report.n_ticks = loop.stats.n_ticks
    report.late_ticks = loop.stats.late_ticks
    report.skipped_slots = loop.stats.skipped_slots
    report.retries = int(getattr(backend, "retry_count", 0))
    report.missed_reads = int(getattr(backend, "missed_reads", 0))
    if loop.rest_problem:
        report.errors.append(loop.rest_problem)
    events = list(getattr(backend, "events", []))
    if events:
        shown = events[:20]
        report.errors.extend(shown)
        if len(events) > len(shown):
            report.errors.append(f"... and {len(events) - len(shown)} more bus events")
    starts = loop.stats.starts
    if len(starts) >= 2:
        period = loop.period_s
        p = np.diff(np.asarray(starts)) * 1000.0
        report.p50_period_ms = float(np.percentile(p, 50))
        report.p99_period_ms = float(np.percentile(p, 99))
        report.jitter_ms = float(np.mean(np.abs(p - period * 1000.0)))


__all__ = ["BackendError", "Interrupted", "PlaybackReport", "play"]
