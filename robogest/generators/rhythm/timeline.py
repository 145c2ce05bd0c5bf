"""Keyframe timelines (minimum-jerk tracks), the wrist paths of moves, and the head track.

The motion is built as keyframe timelines in the angle space of :mod:`~robogest.generators.poses` and
interpolated with minimum-jerk (quintic) segments; a segment is placed by where its wrist speed really peaks
(the wrists move on curves, so not always at the segment's middle). The arm track is in :mod:`.arms`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robogest.generators import lexicon as lx
from robogest.generators.poses import DOF, HEAD_DOFS, READY, dofs_to_rotations
from robogest.generators.rhythm.config import RhythmConfig
from robogest.generators.rhythm.units import GestureEvent
from robogest.motion.skeleton import CANONICAL

#: Wrist-path entries (:meth:`WristPaths.path`) kept per generator: the built-in units' pose pairs number a
#: few hundred, but a live session's late strokes start from whatever pose is held, so over hours the keys would
#: grow without end (measured: 281-906 new entries, about 0.5 KB each, per 6.6 s streamed utterance).
FK_CACHE_SIZE = 4096


@dataclass
class Track:
    """Keyframes ``(t_s, value (K,))`` interpolated with minimum-jerk segments."""

    times: list[float] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)

    def add(self, t_s: float, value: np.ndarray) -> None:
        if self.times and t_s <= self.times[-1] + 1e-6:
            self.values[-1] = value  # same instant: the later key wins
            return
        self.times.append(t_s)
        self.values.append(np.asarray(value, dtype=np.float64))

    @property
    def last_t(self) -> float:
        return self.times[-1]

    @property
    def last_v(self) -> np.ndarray:
        return self.values[-1]

    def sample(self, t_s: np.ndarray) -> np.ndarray:
        """Values at ``t_s (T,)`` -> ``(T, K)``; held constant outside the keys."""
        kt = np.asarray(self.times)
        kv = np.stack(self.values)  # (N, K)
        i = np.clip(np.searchsorted(kt, t_s, side="right") - 1, 0, len(kt) - 1)  # (T,) segment start
        j = np.minimum(i + 1, len(kt) - 1)
        span = np.where(j > i, kt[j] - kt[i], 1.0)
        s = np.clip((t_s - kt[i]) / span, 0.0, 1.0)
        w = (s**3 * (10 - 15 * s + 6 * s**2))[:, None]  # (T, 1) minimum-jerk blend
        return np.asarray(kv[i] + (kv[j] - kv[i]) * w)


class WristPaths:
    """How the wrists move in a minimum-jerk move between two poses, and how short the move may be; cached
    (at most :data:`FK_CACHE_SIZE` pose pairs, oldest dropped first)."""

    def __init__(self, config: RhythmConfig) -> None:
        self.config = config
        self.cache: dict[bytes, tuple[float, float]] = {}

    def path(self, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        """Wrist path of a minimum-jerk move from pose ``a`` to ``b``: the steepest stretch (wrist metres per
        unit of blend) and the fraction of the move's duration at which the faster wrist peaks.

        Poses blend linearly in angle space, so the wrists move on curves whose speed peak is not always at
        the middle of the move; placing a stroke by this fraction puts its real speed peak on the beat.
        """
        key = a.tobytes() + b.tobytes()
        if key not in self.cache:
            if len(self.cache) >= FK_CACHE_SIZE:  # a live session's late strokes start anywhere: keep it bounded
                self.cache.pop(next(iter(self.cache)))  # the oldest entry
            self.cache[key] = _wrist_path(a, b)
        return self.cache[key]

    def min_time_s(self, a: np.ndarray, b: np.ndarray) -> float:
        """Shortest minimum-jerk move from pose ``a`` to ``b`` whose wrist speed stays under the cap (the
        path's steepest stretch times the quintic's peak rate 1.875 / T) and, with ``max_wrist_accel_m_s2``,
        whose wrist acceleration stays under that (its peak 5.77 / T² times the same stretch)."""
        c = self.config
        rate = self.path(a, b)[0]
        t = 1.875 * rate / c.max_wrist_speed_m_s
        if c.max_wrist_accel_m_s2:
            t = max(t, float(np.sqrt(5.7735 * rate / c.max_wrist_accel_m_s2)))
        if c.max_joint_speed_rad_s or c.max_joint_accel_rad_s2:
            d = float(np.abs(b - a).max())  # largest angle change, rad
            if c.max_joint_speed_rad_s:
                t = max(t, 1.875 * d / c.max_joint_speed_rad_s)  # quintic peak velocity 1.875 d / T
            if c.max_joint_accel_rad_s2:
                t = max(t, float(np.sqrt(5.7735 * d / c.max_joint_accel_rad_s2)))  # peak accel 5.77 d / T²
        return t


def _wrist_path(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """:meth:`WristPaths.path`, computed: forward kinematics of 33 blends between ``a`` and ``b``."""
    s = np.linspace(0.0, 1.0, 33)[:, None]  # (S, 1) blend
    rot = dofs_to_rotations(a + (b - a) * s)  # (S, J, 4)
    p = CANONICAL.forward_kinematics(rot, np.zeros((len(s), 3)))  # (S, J, 3)
    w = p[:, [CANONICAL.index("l_wrist"), CANONICAL.index("r_wrist")]]  # (S, 2, 3)
    rate = np.linalg.norm(np.diff(w, axis=0), axis=-1) * (len(s) - 1)  # (S-1, 2) m per unit blend
    mid = 0.5 * (s[1:, 0] + s[:-1, 0])
    u = np.linspace(0.0, 1.0, 201)
    su = u**3 * (10 - 15 * u + 6 * u**2)
    dsu = 30 * u**2 * (1 - u) ** 2
    k = int(np.argmax(rate.max(axis=0)))  # the wrist that moves most
    speed = np.interp(su, mid, rate[:, k]) * dsu
    frac = float(u[np.argmax(speed)]) if speed.max() > 1e-9 else 0.5
    return float(rate.max()), frac


def prep_beat(
    c: RhythmConfig, beats_s: np.ndarray, free_s: float, s0: float, need_s: float, frac: float
) -> tuple[float, float] | None:
    """A beat ``b`` before ``s0`` on which a preparation ending at ``s0`` can peak (its speed peak is at
    ``frac`` of its duration ``d = (s0 - b) / (1 - frac)``): at least ``need_s`` long, starting no earlier
    than ``free_s`` and within ``prep_s``. Of those, the one that best fills ``[free_s, s0]``: the
    preparation flows out of the previous gesture rather than leaving the arms parked.
    Returns ``(beat, start)``."""
    frac = min(max(frac, 0.2), 0.8)
    d = (s0 - beats_s) / (1.0 - frac)
    start = s0 - d
    ok = (beats_s < s0) & (d >= need_s - 1e-9) & (s0 - beats_s <= c.prep_s) & (start >= free_s - 1e-9)
    if not ok.any():
        return None
    k = int(np.argmin(np.where(ok, start - free_s, np.inf)))
    return float(beats_s[k]), float(start[k])


def relax_beat(paths: WristPaths, tr: Track, beats_s: np.ndarray, before_s: float) -> tuple[float, float] | None:
    """In a long gap, the free beat on which to settle into READY with a slow move centred on it (its peak on
    the beat) and the move's half length, seconds; None if none fits."""
    half = max(0.35, paths.min_time_s(tr.last_v, READY) / paths.config.prep_speed_ratio / 2)
    ok = (beats_s - half >= tr.last_t) & (beats_s + half <= before_s)
    return (float(beats_s[ok][0]), half) if ok.any() else None


def head_track(
    events: list[GestureEvent], units: dict[str, lx.GestureUnit], rests: list[tuple[float, float]]
) -> tuple[Track, list[tuple[float, float, float, float]]]:
    """Head keyframes of the head events (nods: prep -> stroke -> hold, back to zero), none overlapping another
    or a rest window; and the shakes, ``(start_s, end_s, hz, amplitude_rad)`` of head yaw."""
    tr = Track()
    zero = np.zeros(len(HEAD_DOFS))
    tr.add(0.0, zero)
    shakes: list[tuple[float, float, float, float]] = []
    busy_until = 0.0
    for e in events:
        u = units[e.unit]
        if u.channel != "head":
            continue
        s0, s1 = e.t_s - u.stroke_s / 2, e.t_s + u.stroke_s / 2
        w0, w1 = s0 - 0.15, s1 + u.hold_s + 0.25
        if w0 < busy_until or any(not (w1 <= r0 or w0 >= r1) for r0, r1 in rests):
            continue
        busy_until = w1
        if u.shake_hz > 0:
            shakes.append((s0, s1, u.shake_hz, e.amplitude * u.stroke[DOF["head_yaw"]]))
            continue
        prep = e.amplitude * u.prep[list(HEAD_DOFS)]
        stroke = e.amplitude * u.stroke[list(HEAD_DOFS)]
        tr.add(w0, zero)
        tr.add(s0, prep)
        tr.add(s1, stroke)
        tr.add(s1 + u.hold_s, stroke)
        tr.add(w1, zero)
    return tr, shakes
