"""The arm track: each arm gesture placed as preparation -> stroke -> hold, with rests and relaxations.

Every move made while speaking peaks ``stroke_lead_s`` before an acoustic beat (preparations and relaxations
are slower than strokes); where speech goes on without a chosen beat the pose is held; in rest windows the arms
sit exactly at REST. A live plan (:class:`~.live.LivePlan`) changes nothing before its committed frames: a
stroke seen too late for its preparation goes straight from the held pose, shortened if it must be.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from robogest.generators import lexicon as lx
from robogest.generators.poses import READY, REST
from robogest.generators.rhythm.config import RhythmConfig
from robogest.generators.rhythm.live import MIN_LATE_STROKE_S, LivePlan
from robogest.generators.rhythm.timeline import Track, WristPaths, prep_beat, relax_beat
from robogest.generators.rhythm.units import GestureEvent

#: A placed stroke: ``(start_s, end_s, event)``.
Placed = tuple[float, float, GestureEvent]


def stroke_peak_s(e: GestureEvent, lead_s: float) -> float:
    """Where the wrist-speed peak of arm event ``e``'s stroke is placed, s: ``lead_s`` before its beat, or on it
    for a tagged gesture (pinned to its word)."""
    return e.t_s if e.source.startswith("tag:") else e.t_s - lead_s


class ArmTimeline:
    """Builds the arm/spine keyframes of one plan, gesture by gesture, in time order with the rest windows.

    ``beats_s (B,)``: the plan's beats, s; ``live``: a streaming plan (``off_s`` is the speech's offset on the
    utterance's clock, ``expected_s`` the expected beats of this plan there), updated as strokes are placed."""

    def __init__(
        self,
        c: RhythmConfig,
        paths: WristPaths,
        units: dict[str, lx.GestureUnit],
        rests: list[tuple[float, float]],
        beats_s: np.ndarray,
        live: LivePlan | None = None,
        off_s: float = 0.0,
        expected_s: frozenset[float] = frozenset(),
    ) -> None:
        self.c, self.paths, self.units, self.rests = c, paths, units, rests
        self.moves_s = beats_s - c.stroke_lead_s  # where preparations and relaxations peak (s)
        self.live, self.off_s, self.expected_s = live, off_s, expected_s
        self.tr = Track()
        self.tr.add(0.0, REST)
        self.placed: list[Placed] = []

    def build(self, events: list[GestureEvent], end_s: float) -> tuple[Track, list[Placed]]:
        """The track over ``[0, end_s]`` s for the arm events among ``events``, and the strokes placed."""
        arm = [e for e in events if self.units[e.unit].channel == "arms"]
        items: list[tuple[float, str, object]] = [
            (stroke_peak_s(e, self.c.stroke_lead_s) - self.units[e.unit].stroke_s / 2, "event", e) for e in arm
        ]
        items += [(r0, "rest", (r0, r1)) for r0, r1 in self.rests]
        items.sort(key=lambda x: (x[0], x[1] != "rest"))
        for _, kind, obj in items:
            if kind == "rest":
                self._rest(*obj)  # type: ignore[misc]
            else:
                self._gesture(obj)  # type: ignore[arg-type]
        if not self.rests or self.rests[-1][1] < end_s - 1e-6:  # speech to the end: back to rest at the end
            tr = self.tr
            tr.add(max(tr.last_t, end_s - self._retract_s(tr.last_v)), tr.last_v)
            tr.add(max(tr.last_t + 0.05, end_s), REST)
        return self.tr, self.placed

    def _retract_s(self, pose: np.ndarray) -> float:
        """How long the move from ``pose`` to REST takes, s."""
        return max(self.c.retract_s, self.paths.min_time_s(pose, REST))

    def _rest(self, r0: float, r1: float) -> None:
        """Retract to REST by ``r0`` (the retraction starts when the pause does) and stay there until ``r1``."""
        tr = self.tr
        if r0 > tr.last_t:
            tr.add(max(tr.last_t, r0 - self._retract_s(tr.last_v)), tr.last_v)
        tr.add(r0, REST)
        tr.add(r1, REST)

    def _no_room(self, s0: float, hold_end: float, pose: np.ndarray, next_rest: list[float]) -> bool:
        """Whether a stroke from ``s0`` held in ``pose`` until ``hold_end`` overlaps the previous gesture or would
        run into the next rest period."""
        if s0 < self.tr.last_t + 1e-6:
            return True  # still busy with the previous gesture
        return bool(next_rest) and hold_end + self._retract_s(pose) > next_rest[0]

    def _gesture(self, e: GestureEvent) -> None:
        """Place arm event ``e``: prepared on an earlier beat as offline, or straight from the held pose."""
        c, tr, paths = self.c, self.tr, self.paths
        u = self.units[e.unit]
        prep_pose = READY + e.amplitude * u.prep
        stroke_pose = READY + e.amplitude * u.stroke
        stroke_s = max(c.stroke_scale * u.stroke_s, paths.min_time_s(prep_pose, stroke_pose))
        f_s = paths.path(prep_pose, stroke_pose)[1]
        pk = stroke_peak_s(e, c.stroke_lead_s)
        s0, s1 = pk - f_s * stroke_s, pk + (1 - f_s) * stroke_s
        hold_end = s1 + c.hold_scale * u.hold_s
        nxt = [r0 for r0, _ in self.rests if r0 > tr.last_t]
        if self._no_room(s0, hold_end, stroke_pose, nxt):
            return
        long_gap = s0 - tr.last_t > c.ready_after_s + 2 * c.prep_s
        relax = relax_beat(paths, tr, self.moves_s, s0 - c.prep_s) if long_gap else None
        # Preparation: a slower move into the prep pose whose speed peak leads an earlier acoustic beat,
        # so it never adds a peak off the beat. Without such a beat the stroke starts from the held pose.
        need = max(c.min_prep_s, paths.min_time_s(tr.last_v, prep_pose) / c.prep_speed_ratio)
        late, prep, move = self._prepare(e, relax, need, prep_pose, s0)
        if late != 0.0:
            prep = None
        else:
            if relax:
                tr.add(relax[0] - relax[1], tr.last_v)
                tr.add(relax[0] + relax[1], READY)
            if prep is not None:
                tr.add(prep[1], tr.last_v)
                tr.add(s0, prep_pose)
                tr.add(s1, stroke_pose)
        if prep is None:  # straight from the held pose (late: shortened to start after the committed frames)
            held = self._from_held(u, pk, stroke_s, stroke_pose, late, nxt)
            if held is None:
                return
            s0, s1, hold_end, stroke_pose, late = held
            if late != 0.0 or not relax:  # else the motion starts with the relaxation
                move = s0
        if self.live is not None:
            off_s = self.off_s
            placed_e = dataclasses.replace(e, t_s=e.t_s + off_s)
            self.live.note(placed_e, late, move + off_s, s0 + off_s, self.expected_s)  # type: ignore[operator]
        self.placed.append((s0, s1, e))
        tr.add(hold_end, stroke_pose)

    def _prepare(
        self, e: GestureEvent, relax: tuple[float, float] | None, need: float, prep_pose: np.ndarray, s0: float
    ) -> tuple[float, tuple[float, float] | None, float | None]:
        """``(late, prep, move)``: how the stroke is placed (0: prepared as offline; < 0: first seen by this live
        plan too late for its preparation or relaxation; > 0: the factor a late stroke was shortened by), the
        preparation's ``(beat, start)`` if prepared, and where the motion starts (None: not known yet)."""
        live, tr, c = self.live, self.tr, self.c
        late = live.placed.get((round(e.t_s + self.off_s, 2), e.unit)) if live is not None else 0.0
        prep, move = None, None
        if late is None or late == 0.0:  # as offline: relax if the gap is long, then prepare on an earlier beat
            held_t, held_v = (relax[0] + relax[1], READY) if relax else (tr.last_t, tr.last_v)
            prep = prep_beat(c, self.moves_s, held_t, s0, need, self.paths.path(held_v, prep_pose)[1])
            move = relax[0] - relax[1] if relax else (s0 if prep is None else prep[1])  # the motion's start
            if late is None:  # first seen by this live plan: too late for its preparation (or relaxation)?
                late = 0.0 if move >= live.commit_s - self.off_s - 1e-6 else -1.0  # type: ignore[union-attr]
        return late, prep, move

    def _from_held(
        self,
        u: lx.GestureUnit,
        pk: float,
        stroke_s: float,
        stroke_pose: np.ndarray,
        late: float,
        nxt: list[float],
    ) -> tuple[float, float, float, np.ndarray, float] | None:
        """A stroke peaking at ``pk`` straight from the held pose (a late one shortened, and scaled down alike so
        its peak speed stays, to start after the committed frames): ``(s0, s1, hold_end, pose, late)``, or None
        if it does not fit."""
        c, tr, paths = self.c, self.tr, self.paths
        d = max(stroke_s, paths.min_time_s(tr.last_v, stroke_pose))
        f_d = paths.path(tr.last_v, stroke_pose)[1]
        if late < 0:
            lo = max(tr.last_t, self.live.commit_s - self.off_s)  # type: ignore[union-attr]
            late = min(1.0, (pk - lo - 0.01) / (f_d * d))
            if late * d < MIN_LATE_STROKE_S:
                return None
        if late > 0:
            stroke_pose = tr.last_v + (stroke_pose - tr.last_v) * late  # same peak speed, shorter
            d *= late
        s0, s1 = pk - f_d * d, pk + (1 - f_d) * d
        hold_end = s1 + c.hold_scale * u.hold_s
        if self._no_room(s0, hold_end, stroke_pose, nxt):
            return None  # no time for the stroke at a natural speed, or it would run into a rest period
        tr.add(s0, tr.last_v)
        tr.add(s1, stroke_pose)
        return s0, s1, hold_end, stroke_pose, late
