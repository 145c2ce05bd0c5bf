"""The default generator, composed: beats and rests (:mod:`.beats`), unit choice (:mod:`.units`), the arm and
head tracks (:mod:`.arms`, :mod:`.timeline`), idle sway and drift (:mod:`.drift`), and for a live stream the
shared plan (:mod:`.live`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.generators import lexicon as lx
from robogest.generators.acoustic import AcousticBeats, band_loudness_db
from robogest.generators.base import Capabilities, Generator, LivePlanState, register_generator
from robogest.generators.poses import DOF, HEAD_DOFS, dofs_to_rotations
from robogest.generators.rhythm import arms, beats, drift, timeline, units
from robogest.generators.rhythm.config import RhythmConfig, check_config
from robogest.generators.rhythm.live import LIVE_DRIFT_RISE_WIDTHS, LivePlan, expected_beats
from robogest.generators.rhythm.units import GestureEvent
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL_PELVIS_HEIGHT_M
from robogest.speech.types import Speech, Word

if TYPE_CHECKING:
    from robogest.generators.meaning import MeaningChooser


@register_generator("rhythm")
class RhythmGenerator(Generator):
    """Rule-based, beat-synchronous gestures from a hand-authored lexicon; works on a fresh install."""

    name = "rhythm"
    capabilities = Capabilities(streaming=True, live_plan=True, rest_windows=True)

    def __init__(
        self, config: RhythmConfig | None = None, repertoire: lx.Repertoire | None = None, **overrides: float | str
    ) -> None:
        base = config or RhythmConfig()
        self.config = RhythmConfig(**{**base.__dict__, **overrides}) if overrides else base
        check_config(self.config)
        self._meaning: MeaningChooser | None = None
        self.repertoire = repertoire or lx.default_repertoire()
        self._paths = timeline.WristPaths(self.config)
        self._fk_cache = self._paths.cache  # the wrist-path cache (bounded: :data:`timeline.FK_CACHE_SIZE`)

    # --- planning -------------------------------------------------------------------------
    def rest_windows(self, speech: Speech) -> list[tuple[float, float]]:
        """Spans ``(t0, t1)`` in which the motion is exactly the rest pose."""
        return beats.rest_windows(self.config, speech)

    def new_live_plan(self, replan_s: float) -> LivePlan:
        """A :class:`LivePlan` for one stream, plans ``replan_s`` seconds apart."""
        return LivePlan(replan_s=replan_s)

    def generate_live(self, speech: Speech, live: LivePlanState, seed: int = 0) -> HumanMotion:
        """:meth:`generate` as one plan of a stream sharing ``live`` (a :class:`LivePlan`)."""
        if not isinstance(live, LivePlan):
            raise InputError(f"rhythm: a live plan must come from new_live_plan(), got {type(live).__name__}")
        return self.generate(speech, seed=seed, live=live)

    def beats(self, speech: Speech, loudness_db: np.ndarray | None = None, stressed: bool = True) -> AcousticBeats:
        """Where strokes may land (:func:`.beats.speech_beats`): acoustic beats outside silent periods and, if
        ``stressed``, the heard words' stressed syllables with no acoustic beat near them."""
        return beats.speech_beats(speech, loudness_db, stressed)

    @staticmethod
    def stressed_syllable_s(w: Word) -> float | None:
        """Where word ``w``'s stressed syllable starts, s (:func:`.beats.stressed_syllable_s`); None if none."""
        return beats.stressed_syllable_s(w)

    def _expected_beats(self, ab: AcousticBeats, speech: Speech, plan: LivePlan) -> tuple[AcousticBeats, set[float]]:
        """``ab`` with the beats a live plan expects (:func:`.live.expected_beats`), and those expected beats."""
        return expected_beats(ab, speech, plan)

    def plan(self, speech: Speech, seed: int = 0, acoustic: AcousticBeats | None = None) -> list[GestureEvent]:
        """Choose arm and head events (time, unit, amplitude) on acoustic beats; deterministic for a seed.

        Order of precedence: inline tags (``^gesture(name)`` in :attr:`Speech.text`), then semantic units
        by priority within each sentence (trigger words; ``"?"`` = the last word of a question), then beat
        units from the statistical interpreter on the remaining beats. A unit is not repeated back to back
        within :data:`.units.NO_REPEAT_S`. Beat decisions are drawn beat by beat in time order, so a prefix of
        the beats (a partial utterance, as when streaming) gets the choices it gets in the whole one.
        ``acoustic`` passes :meth:`beats` already computed (each call otherwise detects them again).
        """
        c = self.config
        if c.gestures == "none" or c.amount <= 0:
            return []
        ab = acoustic if acoustic is not None else self.beats(speech)
        return units.choose_units(c, self.repertoire, speech, ab, seed, self._meaning_chooser)

    def _meaning_chooser(self) -> MeaningChooser:
        """The sentence-embedding chooser (learn extra), loaded on first use."""
        if self._meaning is None:
            from robogest.generators.meaning import MeaningChooser

            self._meaning = MeaningChooser(self.repertoire)
        return self._meaning

    # --- synthesis ------------------------------------------------------------------------
    def stroke_peak_s(self, e: GestureEvent) -> float:
        """Where the wrist-speed peak of arm event ``e``'s stroke is placed, s: ``stroke_lead_s`` before its
        beat, or on it for a tagged gesture (pinned to its word)."""
        return arms.stroke_peak_s(e, self.config.stroke_lead_s)

    def _arm_track(
        self,
        events: list[GestureEvent],
        rests: list[tuple[float, float]],
        end_s: float,
        beats_s: np.ndarray,
        live: LivePlan | None = None,
        off_s: float = 0.0,
        expected_s: frozenset[float] = frozenset(),
    ) -> tuple[timeline.Track, list[arms.Placed]]:
        """Arm/spine keyframes of ``events`` and the placed strokes ``(start_s, end_s, event)``
        (:class:`.arms.ArmTimeline`); ``live``: a streaming plan, updated here."""
        tl = arms.ArmTimeline(self.config, self._paths, self.repertoire.units, rests, beats_s, live, off_s, expected_s)
        return tl.build(events, end_s)

    def strokes(self, speech: Speech, seed: int = 0) -> list[tuple[float, float, GestureEvent]]:
        """The arm strokes :meth:`generate` makes: ``(start_s, end_s, event)``, speed peak at
        :meth:`stroke_peak_s` of the event (``stroke_lead_s`` before ``event.t_s``, on it for tags)."""
        ab = self.beats(speech)
        return self._arm_track(self.plan(speech, seed, ab), self.rest_windows(speech), speech.duration_s, ab.t_s)[1]

    def generate(self, speech: Speech, seed: int = 0, live: LivePlan | None = None) -> HumanMotion:
        """Motion for ``speech``; ``live`` when it is one plan of a stream (:class:`LivePlan`, updated here)."""
        c = self.config
        fps = c.fps or speech.fps
        n = speech.n_frames if fps == speech.fps else round(speech.duration_s * fps)
        t = np.arange(n) / fps  # (T,)
        rests = self.rest_windows(speech)
        db = band_loudness_db(speech.audio, speech.sr)  # (F,) the beats and the drift both follow it
        ab = self.beats(speech, db, stressed=live is None)
        expected: set[float] = set()
        if live is not None:
            ab, expected = self._expected_beats(ab, speech, live)
        events = self.plan(speech, seed, ab)
        if live is not None:
            arm_units = {n for n, u in self.repertoire.units.items() if u.channel == "arms"}
            events = live.keep_started(events, arm_units, speech.offset_s, speech.offset_s + speech.duration_s)
        track = self._arm_track(events, rests, speech.duration_s, ab.t_s, live, speech.offset_s, frozenset(expected))
        dofs = track[0].sample(t)  # (T, D)
        self._add_head(dofs, events, rests, t)
        dofs += self._idle(speech, t, rests, db, ab.t_s, seed, live)
        rot = dofs_to_rotations(dofs)
        root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (n, 1))
        return HumanMotion(fps=fps, rotations=rot, root_pos_m=root)

    def _add_head(
        self, dofs: np.ndarray, events: list[GestureEvent], rests: list[tuple[float, float]], t: np.ndarray
    ) -> None:
        """Add the head's moves at ``t (T,)`` s to ``dofs (T, D)``: nods from the head track, then the shakes."""
        head, shakes = timeline.head_track(events, self.repertoire.units, rests)
        dofs[:, list(HEAD_DOFS)] += head.sample(t)
        for s0, s1, hz, amp in shakes:
            inside = (t >= s0) & (t <= s1)
            ph = (t[inside] - s0) / (s1 - s0)
            dofs[inside, DOF["head_yaw"]] += amp * np.sin(2 * np.pi * hz * (t[inside] - s0)) * np.sin(np.pi * ph) ** 2

    def _idle(
        self,
        speech: Speech,
        t: np.ndarray,
        rests: list[tuple[float, float]],
        db: np.ndarray,
        beats_s: np.ndarray,
        seed: int,
        live: LivePlan | None,
    ) -> np.ndarray:
        """Sway and wrist drift ``(T, D)`` (:meth:`_sway`), offline or for a live plan."""
        c = self.config
        # A live plan speeds the drift up only on the beats whose speed-up rises (from one width before its
        # peak) after the frames played (:meth:`LivePlan.drift_beats`, :data:`LIVE_DRIFT_RISE_WIDTHS`). In real
        # time that leaves the beats it expects (stressed syllables of words that have started): an acoustic
        # beat is heard about 0.15 s before the frames that must move for it, too late. Audio delivered faster
        # than real time is heard in time.
        if live is None:
            drift_beats = beats_s
        else:
            rise_s = c.stroke_lead_s + LIVE_DRIFT_RISE_WIDTHS * c.drift_beat_s
            drift_beats = live.drift_beats(beats_s + speech.offset_s, rise_s) - speech.offset_s
        rng = np.random.default_rng(seed + 7919)
        drift_m_s = c.drift_m_s if live is None else c.live_drift_m_s
        # A live plan's drift keeps a steady radius (that of mid loudness): it plans frames up to 0.6 s beyond the
        # audio heard, so a radius that followed the loudness was rewritten under the frames about to play at
        # each plan, and each rewrite put a speed bump off the beats (see ``live_drift_m_s``).
        loud = drift.loudness(db, t) if live is None else np.full(len(t), 0.5)
        return self._sway(t, rests, rng, loud, speech.offset_s, drift_beats, drift_m_s)

    def _sway(
        self,
        t: np.ndarray,
        rests: list[tuple[float, float]],
        rng: np.random.Generator,
        loud: np.ndarray,
        t0_s: float,
        beats_s: np.ndarray,
        drift_m_s: float,
    ) -> np.ndarray:
        """Idle breathing/sway and wrist drift ``(T, D)`` while speaking (:func:`.drift.sway`)."""
        return drift.sway(self.config, t, rests, rng, loud, t0_s, beats_s, drift_m_s)
