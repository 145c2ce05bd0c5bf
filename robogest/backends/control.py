"""The control loop: the one path from any motion source to a backend, and the one go-to-rest.

A :class:`ControlLoop` connects once, holds the present pose with torque on and then, every tick, takes a target
pose from its current *source*, passes it through the loop's :class:`~robogest.safety.online.OnlineLimiter`
(position, velocity, acceleration and jerk limits at the loop's own rate; its state is the last goal actually
sent) and sends the result with ``backend.write_goal``. Sources, in priority order:

* a :class:`~robogest.trajectory.Trajectory` given to :meth:`ControlLoop.play` (sampled at the loop time,
  optionally starting at a given loop time; the robot first glides to its first pose if it is elsewhere);
* rest, after :meth:`ControlLoop.interrupt` (as fast as the limits allow), until the next ``play``/``set_idle``;
* an idle motion ``f(t_s) -> q (J,)`` set with :meth:`ControlLoop.set_idle` (``t_s`` on the loop clock);
* otherwise the last pose reached is held.

Two ways to run it, sharing every line of the tick:

* **threaded** (default for realtime backends): :meth:`ControlLoop.start` starts a thread ticking at
  ``rate_hz`` on ``time.monotonic`` with an absolute schedule; ``play`` returns at once; a late tick advances
  the loop time (the target) but the goal still moves only one limiter period from the last goal sent;
* **stepped** (``threaded=False``; default for the simulator): ticks run in the caller's thread inside
  :meth:`PlayHandle.wait`, :meth:`ControlLoop.run_for` or :meth:`ControlLoop.step`; a simulated backend is
  advanced by one period per tick, so runs are deterministic.

:meth:`ControlLoop.close` (idempotent) glides to rest, then calls ``backend.shutdown()`` (torque off,
disconnect); :func:`go_to_rest` is the same glide without a running loop, :func:`signals_end_at_rest` the signals
that run it (in :mod:`robogest.backends.rest` and :mod:`robogest.backends.signals`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from robogest.backends.base import Backend, check_goal
from robogest.backends.play_handle import LoopStats, PlayHandle
from robogest.backends.rest import DEFAULT_RATE_HZ, start_pose
from robogest.backends.signals import (
    deferred_signals,
)
from robogest.errors import BackendError, RobogestError
from robogest.robot.config import LIMIT_MARGIN_RAD
from robogest.safety.online import LOOKAHEAD_S, OnlineLimiter
from robogest.trajectory.types import Trajectory, check_matches

#: A play is done when the goal sits within this of the trajectory's last pose, still (radians).
_DONE_TOL_RAD = 1e-4
#: Longest glide to rest before giving up and saying so, loop seconds.
REST_TIMEOUT_S = 10.0


# --- the loop ----------------------------------------------------------------------------------------
class ControlLoop:
    """Persistent control loop on one backend (see the module docstring).

    Parameters
    ----------
    backend : Backend
        Connected by :meth:`start` unless ``is_connected``; shut down by :meth:`close`.
    rate_hz : float
        Ticks per wall-clock second; default 100 Hz.
    on_tick : callable (loop_s, goal_rad), optional
        Called after every tick with the loop time (s) and the goal ``(J,)`` sent (rad); keep it short.
    threaded, wall_clock : bool, optional
        Tick in a background thread; ticks due on the wall clock (a simulated backend is then advanced one period
        per tick, paced like hardware: a live session). Both default to ``backend.realtime``.
    read_back : bool
        Read present positions every tick (a lost servo or hardware error is caught within a tick).
    time_scale : float
        Trajectory seconds per loop second (tests use > 1 to play faster than real time). The limiter, the clock
        and the backend's guard keep the real period, so a sped-up trajectory is followed only as fast as the
        limits allow.
    margin_rad : float
        Targets are kept this far inside the position limits.
    lookahead_s : float
        Trajectories and idle motions are sampled this far ahead of the loop time, making up for the limiter's lag
        (:data:`~robogest.safety.online.LOOKAHEAD_S`).
    stop_within_s : float, optional
        Keep every goal within this many seconds of standing at rest (the limiter's stop envelope: gestures that
        would go farther are cut short), so :meth:`interrupt` is at rest within it. None: no envelope.
    """

    def __init__(
        self,
        backend: Backend,
        rate_hz: float = DEFAULT_RATE_HZ,
        *,
        on_tick: Callable[[float, np.ndarray], None] | None = None,
        threaded: bool | None = None,
        wall_clock: bool | None = None,
        read_back: bool = True,
        time_scale: float = 1.0,
        margin_rad: float = LIMIT_MARGIN_RAD,
        lookahead_s: float = LOOKAHEAD_S,
        stop_within_s: float | None = None,
    ) -> None:
        if not (rate_hz > 0 and time_scale > 0):
            raise ValueError("rate_hz and time_scale must be positive")
        self.backend = backend
        self.robot = backend.robot
        self.rate_hz = float(rate_hz)
        self.period_s = 1.0 / self.rate_hz
        self.on_tick = on_tick
        self.threaded = backend.realtime if threaded is None else bool(threaded)
        self.read_back = read_back
        self.time_scale = float(time_scale)
        self.margin_rad = margin_rad
        self.lookahead_s = float(lookahead_s)
        self.stop_within_s = stop_within_s
        self.limiter: OnlineLimiter | None = None
        self.stats = LoopStats()
        self.rest_q_rad = np.clip(self.robot.rest_q_rad, self.robot.q_min_rad, self.robot.q_max_rad)
        self.rest_problem: str | None = None  #: why rest could not be reached at close (None: it was)
        self._k = 0  # loop time = k * period
        self._wall0 = 0.0
        self._lock = threading.RLock()
        self._play: PlayHandle | None = None
        self._rest: PlayHandle | None = None
        self._idle: Callable[[float], np.ndarray] | None = None
        self._hold: np.ndarray = self.rest_q_rad  # the pose held when nothing plays (set when the loop starts)
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.error: BaseException | None = None  #: why the loop failed (it went to rest, torque off), or None
        self._started = False
        self.closed = False  #: :meth:`close` ran (also after a failure: the loop closes itself)
        self.wall_clock = backend.realtime if wall_clock is None else bool(wall_clock)

    @property
    def resting(self) -> PlayHandle | None:
        """The glide to rest of the last :meth:`interrupt` (``done`` at rest) until a play or idle motion follows."""
        return self._rest

    # --- clock -------------------------------------------------------------------------------------
    @property
    def now_s(self) -> float:
        """Loop time of the next tick, seconds (``rate_hz`` ticks per loop second; starts at 0)."""
        return self._k * self.period_s

    def loop_s_at(self, monotonic_s: float) -> float:
        """Loop time of a ``time.monotonic()`` instant (realtime loops: ticks are due at their loop time after
        start), for ``play(start_at=loop.loop_s_at(t_mono))``."""
        if not self.wall_clock:
            raise RuntimeError("a stepped (simulated) loop has no wall-clock time; give start_at in loop time")
        return monotonic_s - self._wall0

    @property
    def goal_rad(self) -> np.ndarray:
        """Last goal sent ``(J,)``, radians."""
        return np.array(self._lim().q_rad, dtype=float)

    def _lim(self) -> OnlineLimiter:
        if self.limiter is None:
            raise RuntimeError("control loop not started")
        return self.limiter

    # --- life cycle --------------------------------------------------------------------------------
    def start(self) -> ControlLoop:
        """Connect (if needed), hold the present pose, torque on, start ticking (threaded mode)."""
        if self._started:
            return self
        if self.wall_clock:  # hardware (or its stand-in): refuse a robot file whose limits the servos cannot keep
            from robogest.backends.servos.check import require_hardware_safe

            require_hardware_safe(self.robot)
        set_rate = getattr(self.backend, "set_control_rate", None)
        if set_rate is not None:
            set_rate(self.rate_hz)
        if not getattr(self.backend, "is_connected", False):
            self.backend.connect()
        q_now = start_pose(self.backend.read_positions(), self.robot, self.period_s)
        self.backend.write_goal(q_now, source="present pose at start")  # hold, so enabling torque does not jump
        self.backend.confirm_goal()  # a sync write is not acknowledged: a servo that missed it would jump
        self.backend.set_torque(True)
        self._adopt(q_now)
        self._started = True
        if self.threaded:
            self._thread = threading.Thread(target=self._run_thread, name="robogest-control", daemon=True)
            self._thread.start()
        return self

    def _adopt(self, q_now: np.ndarray, v_now: np.ndarray | None = None, a_now: np.ndarray | None = None) -> None:
        self.limiter = OnlineLimiter.for_robot(
            self.robot, self.period_s, q_now, margin_rad=self.margin_rad, stop_within_s=self.stop_within_s
        )
        if v_now is not None:
            self.limiter.take_over(self.limiter.q_rad, v_now, np.zeros_like(v_now) if a_now is None else a_now)
        self._hold = self.limiter.q_rad.copy()
        self._wall0 = time.monotonic()
        self._k = 0

    def play(
        self, trajectory: Trajectory, start_at: float | None = None, approach_within_rad: float = 0.0
    ) -> PlayHandle:
        """Play ``trajectory`` from loop time ``start_at`` (default: now; from a monotonic time: :meth:`loop_s_at`);
        returns at once.

        The robot first glides to the trajectory's first pose and comes to a stop there, unless the goal is already
        within ``approach_within_rad`` of it on every joint: then the trajectory starts at once and the limiter
        takes up the difference (a live utterance starting from rest or idle motion keeps its time with the
        speech).

        It must match the robot definition (:func:`~robogest.trajectory.types.check_matches`: joints in the robot's
        order, its limits and rest). A trajectory already playing is replaced (its handle gets ``interrupted``); the
        new one starts from wherever the goal is, within the limits.
        """
        check_matches(trajectory, self.robot)
        self._check_alive()
        h = PlayHandle(self, trajectory, start_at, approach_within_rad)
        with self._lock:
            self._cancel(self._play)
            self._cancel(self._rest)
            self._rest = None
            self._play = h
        return h

    def set_idle(self, f: Callable[[float], np.ndarray] | None) -> None:
        """Idle motion ``f(loop_s) -> q (J,)`` rad, used when nothing plays (None: hold the last pose)."""
        with self._lock:
            self._idle = f
            if f is not None:
                self._cancel(self._rest)
                self._rest = None

    def interrupt(self) -> PlayHandle:
        """Stop what plays and glide to rest as fast as the limits allow; the handle is ``done`` at rest."""
        self._check_alive()
        with self._lock:
            self._cancel(self._play)
            self._play = None
            if self._rest is None or self._rest.done:
                self._rest = PlayHandle(self, None, None)
                self._rest.phase = "run"
            return self._rest

    def close(self) -> str | None:
        """Glide to rest, then ``backend.shutdown()`` (torque off, disconnect). Idempotent.

        Returns None when rest was reached, else the reason it was not (also in :attr:`rest_problem`).
        """
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()  # a failing thread closes the loop itself: wait for its glide too
        if self.closed:
            return self.rest_problem
        self.closed = True
        with self._lock:
            self._cancel(self._play)
            self._play = None
            self._idle = None
        # A signal that arrives from here on is raised once the robot is at rest with torque off: raised in the
        # glide, it would start the backend's own glide over from a standstill and could cut the torque-off writes
        # short (some servos left on).
        with deferred_signals():
            try:
                if self._started and self.limiter is not None:
                    self.rest_problem = self._glide_to_rest()
            finally:
                self.backend.shutdown()
        return self.rest_problem

    def __enter__(self) -> ControlLoop:
        try:
            return self.start()
        except BaseException:
            self.close()  # start() may fail after torque went on (a servo that missed its write): turn it off
            raise

    def __exit__(self, et: type[BaseException] | None, *exc: object) -> None:
        problem = self.close()
        if et is None and self.error is not None:
            raise self.error  # the loop failed (and went to rest) while the block went on: say so
        if et is None and problem:
            raise BackendError(f"{self.robot.name}: {problem}; torque off attempted")

    # --- running -----------------------------------------------------------------------------------
    def step(self) -> None:
        """One tick now (stepped loops; a threaded loop ticks by itself)."""
        if self.threaded:
            raise RuntimeError("a threaded control loop ticks by itself; use threaded=False to step it")
        self._check_alive()
        self._tick_paced()

    def run_for(self, seconds: float) -> None:
        """Tick for ``seconds`` of loop time (stepped) or wait that long (threaded)."""
        if self.threaded:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                self._check_alive()
                time.sleep(min(0.05, max(0.0, end - time.monotonic())))
            return
        for _ in range(max(0, round(seconds * self.rate_hz))):
            self.step()

    def _wait(self, h: PlayHandle, timeout_s: float | None) -> None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not h.done:
            if deadline is not None and time.monotonic() >= deadline:
                return
            if self.threaded:
                self._check_alive()
                h._finished.wait(0.05)  # short waits: signals reach the main thread between them
            else:
                self.step()

    def _check_alive(self) -> None:
        if self.error is not None:
            raise self.error
        if self.closed:
            raise RuntimeError("control loop closed")
        if not self._started:
            raise RuntimeError("control loop not started; call start() first")

    def _run_thread(self) -> None:
        try:
            while not self._stop.is_set():
                self._tick_paced()
        except BaseException as e:
            self.error = e
            with self._lock:
                for h in (self._play, self._rest):
                    if h is not None:
                        h._fail(e)
            self.close()

    def _tick_paced(self) -> None:
        """Wait for this tick's slot (realtime) or advance the simulation (stepped), then tick."""
        if self.wall_clock:
            wall_period = self.period_s
            due = self._wall0 + self._k * wall_period
            now = time.monotonic()
            if now < due:
                time.sleep(due - now)
                now = time.monotonic()
            behind = now - due
            if behind > 0.5 * wall_period:
                self.stats.late_ticks += 1
            if behind >= wall_period:  # whole slots lost: the target time jumps, the goal does not
                skip = int(behind / wall_period)
                self._k += skip
                self.stats.skipped_slots += skip
            self.stats.starts.append(now)
        with deferred_signals():
            self._tick()
        self._k += 1
        if not self.backend.realtime:
            self.backend.advance(self.period_s)

    # --- the tick ----------------------------------------------------------------------------------
    def _cancel(self, h: PlayHandle | None) -> None:
        if h is not None and not h.done:
            h.phase = "interrupted"
            h._mark("interrupted", self.now_s)

    def _target(self, t: float) -> tuple[np.ndarray, np.ndarray | None, PlayHandle | None]:
        """Target pose ``(J,)`` rad, its velocity (rad/s, or None) and the handle it belongs to."""
        h = self._play
        if h is not None and h.trajectory is not None:
            tr = h.trajectory
            if h.phase == "wait" and (h.start_at is None or t >= h.start_at - 1e-9):
                h.phase = "approach"
                h.held = self._lim().q_rad.copy()
            if h.phase == "approach":
                first = self._lim().clamp_target(tr.sample(0.0))
                gap = np.max(np.abs(self._lim().q_rad - first))
                if (gap <= _DONE_TOL_RAD and self._lim().still) or gap <= h.approach_within_rad:
                    h.phase = "run"
                    h.t_run0 = t
                    h._mark("started", t)
                    if h.on_start is not None:
                        h.on_start()
                else:
                    return first, None, h
            if h.phase in ("run", "finish"):
                tt = (t - h.t_run0) * self.time_scale
                if h.progress is not None:
                    h.progress(min(tt, tr.duration_s), tr.duration_s)
                if tt >= tr.duration_s:
                    h.phase = "finish"
                    return tr.sample(tr.duration_s), None, h
                ahead = tt + self.lookahead_s  # the limiter lags; aiming ahead makes up for it
                return tr.sample(ahead), tr.sample_velocity(ahead), h
        if self._rest is not None:
            return self.rest_q_rad, None, self._rest
        if self._idle is not None:
            return np.asarray(self._idle(t + self.lookahead_s), dtype=float), None, None
        return self._hold, None, None

    def _source_name(self, h: PlayHandle | None) -> str:
        if h is not None and h.trajectory is not None:
            return "trajectory playback"
        if h is not None:
            return "control loop, glide to rest"
        return "control loop, idle motion" if self._idle is not None else "control loop, holding"

    def _tick(self) -> None:
        lim = self._lim()
        t = self.now_s
        with self._lock:
            target, target_v, h = self._target(t)
            if not np.all(np.isfinite(target)):  # a source's bug: stop (and glide to rest), never brake silently
                check_goal(target, self.robot, lim.q_rad, self.period_s, self._source_name(h))
            if h is None or h.trajectory is not None:  # gestures and idle motion, not the glide to rest
                shaped = self.backend.shape_target(target, self.rest_q_rad)  # the health governor, if any
                if target_v is not None and not np.array_equal(shaped, target):
                    target_v = None  # a scaled pose no longer moves at the trajectory's velocity
                target = shaped
            q = lim.propose(target, target_v)
            self.backend.write_goal(q, source=self._source_name(h))
            lim.commit()
            departs = h is not None and h.held is not None and np.max(np.abs(q - h.held)) > 1e-9
            if departs and h is not None and "first_goal" not in h.events:
                h._mark("first_goal", t)
            if h is not None and (h.phase == "finish" or h is self._rest) and lim.settled(_DONE_TOL_RAD):
                h.phase = "done"
                h._mark("done", t)
                self._hold = lim.q_rad.copy()
                if h is self._play:
                    self._play = None
        if self.read_back:
            self.backend.read_positions()
        self.stats.n_ticks += 1
        if self.on_tick is not None:
            self.on_tick(t, q)

    # --- rest --------------------------------------------------------------------------------------
    def _glide_to_rest(self) -> str | None:
        """Tick towards rest (in the caller's thread) until there and still; then let the joints settle."""
        self._stop.set()
        with self._lock:
            self._play = None
            self._idle = None
            self._rest = PlayHandle(self, None, None)
            self._rest.phase = "run"
            rest = self._rest
        self.backend.stopping = True  # faults already reported no longer cut the glide short (Backend.stopping)
        timeout_s = self._rest_timeout_s()
        try:
            for _ in range(int(timeout_s * self.rate_hz) + 1):
                if rest.done:
                    break
                self._tick_paced()
        except RobogestError as e:
            return f"could not reach rest ({e})"
        if not rest.done:
            return f"did not reach rest within {timeout_s:.3g} s"
        if np.any(self._lim().q_rad != self.rest_q_rad):  # settled within rounding (a glide that took over a motion)
            try:
                self.backend.write_goal(self.rest_q_rad, source="control loop, glide to rest")
            except RobogestError as e:
                return f"could not reach rest ({e})"
            self._lim().reset(self.rest_q_rad)
            if not self.backend.realtime:
                self.backend.advance(self.period_s)  # one more tick of simulated time
        self._settle()
        return None

    def glide_from(self, q0: np.ndarray, v0: np.ndarray | None = None, a0: np.ndarray | None = None) -> str | None:
        """Not started: take over a motion at ``q0 (J,)`` rad (``v0``, ``a0``: or still), glide to rest here."""
        self._adopt(q0, v0, a0)
        self._started = True
        return self._glide_to_rest()

    def _rest_timeout_s(self) -> float:
        """How long the glide to rest may take before it is given up: :data:`REST_TIMEOUT_S`, or longer for slow
        limits (1.5 times the time-optimal bound, plus 2 s): a timeout turns torque off away from rest."""
        try:
            bound = self._lim().time_to_reach_s(self.rest_q_rad)
        except RobogestError:
            return REST_TIMEOUT_S
        return max(REST_TIMEOUT_S, 1.5 * bound + 2.0)

    def _settle(self, tol_rad: float = 0.02, timeout_s: float = 0.5) -> None:
        """Hold rest until the joints get there (servos lag their goal), so torque goes off at rest."""
        for _ in range(int(timeout_s * self.rate_hz) + 1):
            if np.max(np.abs(self.backend.read_positions() - self.rest_q_rad)) <= tol_rad:
                return
            if self.backend.realtime:
                time.sleep(self.period_s)
            else:
                self.backend.advance(self.period_s)
