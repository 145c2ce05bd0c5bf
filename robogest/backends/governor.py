"""Health governor: gestures get smaller, slower and rarer as the servos heat up or strain.

The servo backends read temperature and load at a low rate during playback (round robin, see
:meth:`~robogest.backends.servos.bus.ServoBackend.check_health`) and feed them here; the player passes every
target through :meth:`Governor.shape`. Above the hard limits the backend still stops the motion, goes to rest
and turns torque off; the governor acts below them, so a long monologue can finish instead of being cut off.

How a target is shaped: ``rest + a * (q - rest)``. Scaling the deviation from rest by ``a`` scales the
gesture's amplitude, and with the same timing its speed and acceleration, by ``a``. The target factor falls
linearly from 1 at the warning level to ``min_factor`` at the hard limit (the lower of the temperature and
load factors, hottest/most loaded servo). ``a`` follows it at up to ``extra_speed_rad_s / dev`` per second
(``dev``: the target's largest deviation from rest; at most ``max_rate_per_s``), so a changing ``a`` adds at
most ``extra_speed_rad_s`` (0.1 rad/s) to any joint: it changes fast near rest and slowly mid-gesture.

Rests get longer: while the target factor is below 1, a rest (the target within ``rest_tol_rad`` of rest
for ``rest_min_s`` at least, not just a crossing) steers ``a`` to 0 (invisible at rest) and keeps it there
for ``hold_max_s * (1 - target) / (1 - min_factor)`` after the target leaves rest; the next gesture then
grows back in only as ``a`` recovers, which happens near rest, so part of it is skipped rather than rushed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np


@dataclass
class GovernorConfig:
    """Levels and rates. Temperatures in °C, loads in % of the servo's maximum, times in seconds."""

    warn_temperature_c: float = 55.0
    max_temperature_c: float = 65.0
    warn_load_pct: float = 60.0
    max_load_pct: float = 100.0
    min_factor: float = 0.4
    extra_speed_rad_s: float = 0.1  #: most speed a changing factor may add to a joint
    max_rate_per_s: float = 5.0  #: fastest change of the factor (near rest)
    rest_tol_rad: float = 0.05
    rest_min_s: float = 0.25  #: a target within rest_tol_rad of rest this long is a rest, not a crossing
    hold_max_s: float = 2.0
    load_smoothing_s: float = 2.0  #: time constant of the moving average applied to |load|
    new_playback_after_s: float = 1.0  #: a gap between targets this long starts over at factor 1


@dataclass
class Governor:
    """State of the governor for one robot; feed it readings with :meth:`observe`, shape targets with :meth:`shape`."""

    config: GovernorConfig = field(default_factory=GovernorConfig)
    enabled: bool = True
    factor: float = 1.0  #: the factor applied to the last target
    temperatures_c: dict[int, float] = field(default_factory=dict)
    loads_pct: dict[int, float] = field(default_factory=dict)  #: smoothed |load| per servo
    _last_obs_s: dict[int, float] = field(default_factory=dict)
    _last_shape_s: float | None = None
    _hold_until_s: float = 0.0
    _rest_since_s: float | None = None
    min_factor_seen: float = 1.0  #: lowest target factor the readings called for during shaping (for reports)
    holds: int = 0  #: rests that were lengthened

    def observe(self, servo_id: int, temperature_c: float, load_pct: float | None, now_s: float | None = None) -> None:
        """One health reading of one servo (``load_pct`` None: the servo reports no load percentage)."""
        now = time.monotonic() if now_s is None else now_s
        self.temperatures_c[servo_id] = float(temperature_c)
        if load_pct is None:
            return
        prev, t_prev = self.loads_pct.get(servo_id), self._last_obs_s.get(servo_id)
        load = abs(float(load_pct))
        if prev is None or t_prev is None:
            self.loads_pct[servo_id] = load
        else:
            w = 1.0 - np.exp(-max(0.0, now - t_prev) / self.config.load_smoothing_s)
            self.loads_pct[servo_id] = prev + w * (load - prev)
        self._last_obs_s[servo_id] = now

    def target_factor(self) -> float:
        """The factor the readings call for, in ``[min_factor, 1]``."""
        c = self.config

        def ramp(value: float, warn: float, limit: float) -> float:
            x = np.clip((value - warn) / max(limit - warn, 1e-9), 0.0, 1.0)
            return float(1.0 - (1.0 - c.min_factor) * x)

        f = 1.0
        if self.temperatures_c:
            f = min(f, ramp(max(self.temperatures_c.values()), c.warn_temperature_c, c.max_temperature_c))
        if self.loads_pct:
            f = min(f, ramp(max(self.loads_pct.values()), c.warn_load_pct, c.max_load_pct))
        return f

    def shape(self, q_target_rad: np.ndarray, rest_q_rad: np.ndarray, now_s: float | None = None) -> np.ndarray:
        """``rest + a * (q_target - rest)``, ``(J,)`` radians; see the module docstring for how ``a`` moves."""
        q: np.ndarray = np.array(q_target_rad, dtype=float)  # a copy: the caller may keep its target
        if not self.enabled:
            return q
        c = self.config
        now = time.monotonic() if now_s is None else now_s
        if self._last_shape_s is not None and now - self._last_shape_s > c.new_playback_after_s:
            self.reset()  # a new playback: its first target is where the robot already is, so start at 1
        dt = 0.0 if self._last_shape_s is None else max(0.0, now - self._last_shape_s)
        self._last_shape_s = now
        rest = np.asarray(rest_q_rad, float)
        dev = float(np.max(np.abs(q - rest))) if q.size else 0.0
        goal = self.target_factor()
        self.min_factor_seen = min(self.min_factor_seen, goal)
        resting = False
        if dev <= c.rest_tol_rad:
            self._rest_since_s = now if self._rest_since_s is None else self._rest_since_s
            resting = now - self._rest_since_s >= c.rest_min_s
        else:
            if self._rest_since_s is not None and now - self._rest_since_s >= c.rest_min_s and goal < 1.0:
                self._hold_until_s = now + c.hold_max_s * (1.0 - goal) / max(1.0 - c.min_factor, 1e-9)
                self.holds += 1
            self._rest_since_s = None
        if goal < 1.0 and (resting or now < self._hold_until_s):
            goal = 0.0  # during a rest (invisible there) and the hold after it
        step = dt * min(c.max_rate_per_s, c.extra_speed_rad_s / max(dev, 1e-9))
        self.factor = float(np.clip(goal, self.factor - step, self.factor + step))
        shaped: np.ndarray = rest + self.factor * (q - rest)
        return shaped

    def reset(self) -> None:
        """A new playback starts at full amplitude (the first target is where the robot already is)."""
        self.factor = 1.0
        self._last_shape_s = None
        self._hold_until_s = 0.0
        self._rest_since_s = None

    def state(self) -> dict[str, float]:
        """For reports: the factor now and the lowest so far, the hottest servo, the largest smoothed load."""
        return {
            "factor": self.factor,
            "target_factor": self.target_factor(),
            "lowest_factor": self.min_factor_seen,
            "max_temperature_c": max(self.temperatures_c.values(), default=float("nan")),
            "max_load_pct": float(max(self.loads_pct.values(), default=float("nan"))),
            "warn_temperature_c": self.config.warn_temperature_c,
            "lengthened_rests": float(self.holds),
        }
