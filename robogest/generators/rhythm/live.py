"""The live plan a streaming planner shares with the generator across the plans of one utterance."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from robogest.generators.acoustic import AcousticBeats
from robogest.generators.rhythm.beats import HEARD_AFTER_S, STRESS_PROMINENCE, stressed_syllable_s
from robogest.generators.rhythm.units import GestureEvent
from robogest.speech.types import Speech

#: Live plans: the drift speeds up on a beat when its speed-up, from this many widths (``drift_beat_s``) before its
#: peak, comes after the frames played (:meth:`LivePlan.drift_beats`). Calibrated on the BEAT2 calibration half
#: only, streamed in real time (``bench_live``'s measure, robot goals, 10 seeds), with the drift's radius then still
#: following the loudness: 0 / 1 / 3 widths gave stroke-sync z 4.22 / 4.67 / 4.46 (before, on the expected beats
#: whatever was played, and forgotten once heard: 4.46); re-checked with the live plans' steady radius: 4.66 / 5.42 /
#: 5.35.
LIVE_DRIFT_RISE_WIDTHS = 1.0
#: Live plans: a word not heard yet in which eSpeak NG stresses no syllable (most function words) is expected to
#: bring a beat this long after its start, seconds. Calibrated on the BEAT2 calibration half only, streamed at real
#: time (``bench_live.bench_sync``'s stream, 10 seeds), when every word was expected this way: 0.05 / 0.08 / 0.11 s
#: gave stroke-sync z 2.51 / 2.93 / 2.87 (the median offset of its stressed vowels from the starts of content words
#: is 0.08 s, of function words 0.03 s).
WORD_BEAT_S = 0.08
#: Live plans: a beat within this many seconds of one a plan has already used (a started gesture, an expected beat a
#: stroke was placed on, a started drift speed-up) is taken for the same beat, heard again a little elsewhere.
SAME_BEAT_S = 0.12
#: Live plans: a stroke seen too late for its natural length is shortened (and scaled down alike, so its peak
#: speed stays) to no less than this, seconds, or skipped.
MIN_LATE_STROKE_S = 0.1


@dataclass
class LivePlan:
    """What a streaming planner and the generator share across the plans of one utterance (utterance clock, s).

    A live stream hears each beat only about 0.15 s before the robot must move for it, too late for the
    preparation an offline plan gives a stroke, and the frames already sent are final. So a live plan (i) lets
    no new stroke change the motion before :attr:`commit_s`: a stroke first seen after its preparation should
    have started goes straight from the held pose, shortened if it must be; (ii) expects a beat on the stressed
    syllable of each word that has started but whose stressed syllable has not been heard yet (its place in the
    word from eSpeak NG's lexicon, :mod:`robogest.speech.stress`; :data:`WORD_BEAT_S` after the start of a word
    without one), which gives the look-ahead plus the word's lead on its stressed syllable as warning; (iii)
    remembers how it placed each stroke, which gestures have started, which expected beats got one and on which
    beats the drift's speed-up has started, so later plans, which hear more, keep what has started playing.

    Attributes
    ----------
    commit_s : float
        Frames before this are played (final), seconds.
    replan_s : float
        The next plan comes about this much later, seconds: a stroke that starts before ``commit_s + replan_s``
        will be playing by then, so the expected beat it is on is kept.
    placed : dict
        ``(beat_s, unit) -> scale``: how each stroke was first placed; 0 for prepared as offline, else the
        factor a late stroke from the held pose was shortened by (1: not shortened).
    expected_s : set of float
        Expected (word) beats on which a stroke was placed: kept, in place of the heard beat near them.
    started : dict
        ``round(beat_s, 2) -> GestureEvent`` (utterance clock): arm gestures whose motion (preparation,
        relaxation or stroke) starts before ``commit_s + replan_s``. Later plans keep them as they are, whatever
        they now hear: a beat's prominence is judged against more speech each time, and the choices drawn after
        a changed beat change too, so a plan could drop a gesture the robot is already moving into.
    drift_s : set of float
        Beats (rounded to 1 ms) on which the drift's speed-up (``drift_beat_rad``) rises before
        ``commit_s + replan_s`` (:meth:`drift_beats`): later plans keep them, heard or not.
    """

    commit_s: float = -math.inf
    replan_s: float = 0.1
    placed: dict[tuple[float, str], float] = field(default_factory=dict)
    expected_s: set[float] = field(default_factory=set)
    started: dict[float, GestureEvent] = field(default_factory=dict)
    drift_s: set[float] = field(default_factory=set)

    def drift_beats(self, beats_s: np.ndarray, rise_s: float) -> np.ndarray:
        """The beats ``(B,)`` the drift speeds up on, utterance clock, s, from this plan's ``beats_s (B0,)``, whose
        speed-ups rise from ``rise_s`` before them: those already rising (:attr:`drift_s`) and those that rise
        after :attr:`commit_s`, none within :data:`SAME_BEAT_S` of one already rising. Played frames never get
        a speed-up they did not have (the rest of a rise cut by the splice is blended in), and one that started
        always finishes, whatever later plans hear."""
        kept = np.array(sorted(self.drift_s))
        new = {
            round(float(b), 3)
            for b in beats_s
            if b - rise_s >= self.commit_s and (kept.size == 0 or np.abs(kept - b).min() >= SAME_BEAT_S)
        }
        out = np.array(sorted(self.drift_s | new))
        self.drift_s.update(b for b in new if b - rise_s < self.commit_s + self.replan_s)
        return out

    def note(self, e: GestureEvent, late: float, move_s: float, stroke_s: float, expected: frozenset[float]) -> None:
        """Note how arm event ``e`` was placed (all on the utterance clock): its motion starts at ``move_s``, its
        stroke at ``stroke_s``. What plays before the next plan stays: the gesture, and the expected beat it is
        on (until then the heard beat, when it comes, may still move it)."""
        self.placed.setdefault((round(e.t_s, 2), e.unit), late)
        due = self.commit_s + self.replan_s
        if move_s < due:
            self.started.setdefault(round(e.t_s, 2), e)
        t = round(e.t_s, 3)
        if t in expected and stroke_s < due:
            self.expected_s.add(t)

    def keep_started(
        self, events: list[GestureEvent], arms: set[str], off_s: float, end_s: float
    ) -> list[GestureEvent]:
        """``events`` of a plan over ``[off_s, end_s)`` (its clock starts at ``off_s``) with the started gestures
        in it put back in place of any arm event (units ``arms``) within :data:`SAME_BEAT_S` of them."""
        kept = [dataclasses.replace(e, t_s=e.t_s - off_s) for t, e in self.started.items() if off_s <= t < end_s]
        if not kept:
            return events
        near = np.array([k.t_s for k in kept])
        out = [e for e in events if e.unit not in arms or np.abs(near - e.t_s).min() >= SAME_BEAT_S] + kept
        return sorted(out, key=lambda e: (e.t_s, e.source == "beat"))


def expected_beats(ab: AcousticBeats, speech: Speech, live: LivePlan) -> tuple[AcousticBeats, set[float]]:
    """``ab`` plus a beat on the stressed syllable (:func:`~.beats.stressed_syllable_s`; :data:`WORD_BEAT_S` after
    the start of a word in which eSpeak NG stresses no syllable) of each word that has no beat and whose syllable
    is not heard yet, and the expected beats a stroke was already placed on (replacing heard beats within
    :data:`SAME_BEAT_S` of them), of prominence :data:`STRESS_PROMINENCE` (a stressed syllable with no acoustic
    evidence yet, as offline). Also returns the expected beats, on the utterance's clock (rounded to 1 ms)."""
    off, heard = speech.offset_s, speech.heard_s
    t, p = list(ab.t_s), list(ab.prominence)
    expected = {s for s in live.expected_s if off <= s < off + speech.duration_s}
    if heard is not None:
        for w in speech.words:
            syl = stressed_syllable_s(w)
            heard_from, at = (w.start_s, w.start_s + WORD_BEAT_S) if syl is None else (syl, syl)
            if heard_from + HEARD_AFTER_S > heard and not any(w.start_s - 0.1 <= b <= w.end_s for b in t):
                expected.add(round(at + off, 3))
    for e in sorted(expected):
        keep = [i for i, b in enumerate(t) if abs(b + off - e) > SAME_BEAT_S]
        t, p = [t[i] for i in keep] + [e - off], [p[i] for i in keep] + [STRESS_PROMINENCE]
    order = np.argsort(t, kind="stable")
    return AcousticBeats(np.asarray(t, float)[order], np.asarray(p, float)[order]), expected
