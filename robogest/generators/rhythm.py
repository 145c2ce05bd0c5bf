"""The default generator: rhythm-aware, rule-based, no trained weights.

Strokes land on acoustic beats (:mod:`acoustic`: the generator's own detector of loudness rises, never
pseudo-beats): each stroke's wrist-speed peak is at its beat. Preparations are slower and peak on an
earlier beat, so every move made while speaking peaks on a beat; where speech goes on without a chosen
beat the pose is held. Inline tags and trigger words (by priority within a sentence) pick semantic units
from the data-driven repertoire (:mod:`lexicon`), a statistical interpreter (Rhythmic Gesticulator §7.4.6)
picks beat units, and every long silent period is spent exactly at the rest pose (the silent-period hint,
Rhythmic Gesticulator §6.4.1).

The motion is built as keyframe timelines in the angle space of :mod:`poses` and interpolated with
minimum-jerk (quintic) segments; a segment is placed by where its wrist speed really peaks (the wrists move
on curves, so not always at the segment's middle).

A live stream plans with a :class:`LivePlan`: it hears a beat only about 0.15 s before the robot must move
for it, so a stroke seen too late for its preparation goes straight from the held pose (shortened if it must
be) and never changes frames already played, and each word not heard yet is expected to bring a beat. Without
a live plan (a whole utterance) the output is as described above.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtr

from robogest.errors import InputError
from robogest.generators import lexicon as lx
from robogest.generators.acoustic import HOP_S, AcousticBeats, acoustic_beats, band_loudness_db
from robogest.generators.animated_speech import resolve_unit
from robogest.generators.base import Generator, register_generator
from robogest.generators.poses import DOF, HEAD_DOFS, N_DOF, READY, REST, dofs_to_rotations
from robogest.generators.tags import align_words, mode_spans, parse_tags, sentences
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M
from robogest.speech.stress import stress_fraction
from robogest.speech.types import Speech, Word


@dataclass(frozen=True)
class RhythmConfig:
    """Timing and style of the default generator (seconds, radians).

    The defaults were calibrated on the first half (0-32 s) of the BEAT2 sample (speaker "scott") only;
    ``benchmarks/bench_generalize.py`` reports them on held-out speech (README, Evaluation): about 0.77x
    the speaker's mean wrist speed and acceleration during speech on the calibration half.

    Attributes
    ----------
    fps : float or None
        Output frame rate; None uses the speech's feature rate.
    prep_s : float
        A preparation is centred on an acoustic beat at most this long before its stroke starts (it lasts
        at least ``min_prep_s`` and is slow enough for ``prep_speed_ratio``); without such a beat the
        stroke starts straight from the held pose. Gaps longer than ``ready_after_s + 2 prep_s`` relax to
        READY, on a free beat.
    min_prep_s : float
        Shortest preparation.
    gesture_rate : float
        Probability scale of gesturing on an ordinary beat (keywords always gesture): the chance is
        ``min(1, gesture_rate * (0.35 + 0.65 * prominence))``, so 3 gestures on every beat that fits.
    amplitude : float
        Global scale of every gesture offset.
    retract_s : float
        Time allowed to reach rest after a silent period starts.
    rest_lead_s : float
        Rest is left this long before speech resumes.
    min_rest_span_s : float
        Silent periods at least this long are spent at rest; shorter pauses hold the ready pose.
    ready_after_s : float
        After a hold, return to the ready pose if no preparation starts within this time.
    sway_rad : float
        Amplitude of idle breathing/sway while speaking.
    head_beat_prob : float
        Probability of a small head beat on a prominent beat.
    max_wrist_speed_m_s : float
        Cap on the wrist speed peak of any move (BEAT2's speaker: 99th percentile ~2.1 m/s); moves are
        lengthened, or a gesture skipped, to stay under it.
    max_wrist_accel_m_s2 : float or None
        Cap on the wrist acceleration peak of any move (a quintic's 5.77 x path / T²): moves are lengthened to
        stay under it. 15 m/s² is the BEAT2 speaker's 99th percentile during speech on the calibration half
        (30 fps differences), set from his motion, not searched. Without it strokes peaked at up to 30 m/s²
        (his maximum: 22) and the eSpeak clips' acceleration ran 1.23-1.49x his (their semantic units have
        short, wide strokes); with it 1.04-1.34x, and 1.02x on both BEAT2 halves, at a cost of stroke-sync
        z 6.44 -> 6.10 on the calibration half (held-out half 5.53 -> 5.55; ``bench_generalize.py``,
        10 seeds). None turns it off.
    stroke_scale : float
        Multiplies every unit's stroke duration (longer strokes: lower acceleration, same beat timing).
    prep_speed_ratio : float
        Preparations peak at most at this fraction of ``max_wrist_speed_m_s``, so the stroke stays the
        fastest phase (and leaving rest after a pause is unhurried).
    hold_scale : float
        Multiplies every unit's post-stroke hold.
    amount : float
        Designer control in [0, 2]: scales how often beats get a gesture (x amount) and gesture size
        (x (0.5 + 0.5 amount)); 0 gestures not at all. ``--style calm|neutral|lively`` = 0.5 / 1 / 1.5.
    gestures : str
        ``"auto"``, or ``"none"`` for idle breathing and the rest behaviour only.
    drift_m_s, drift_hz : float
        Drift of each wrist while speaking, between and under the gestures: a small circle at this speed
        (m/s, times ``amount``; at mid loudness with ``drift_loudness``; none with ``gestures="none"``) and
        frequency (radius about 10 cm at 0.3 m/s). On the calibration half a steady 0.3 m/s brought wrist speed
        from 0.42x to 0.7x the speaker's and the Hellinger distance from 0.64 to about 0.43, at a cost in
        stroke-sync z (3.7 -> about 3.1, 10 seeds): the drift shifts the strokes' speed peaks a little. 0.3 Hz
        kept more z (3.3) with 16 cm circles, 0.8 Hz less (2.8).
    drift_loudness : float
        How much the drift follows the voice, in [0, 1]: each wrist's circle has ``(1 - k + 2 k loud(t))`` times
        its radius, so its speed, ``loud`` the generator's band loudness (:func:`acoustic.band_loudness_db`)
        smoothed over :data:`LOUDNESS_SMOOTH_S` and scaled to [0, 1] between its 20th and 95th percentile
        (digital silence left out); 0 is a steady circle. A speaker's hands are never still and move more as
        the voice rises, so the hands speed up and slow down with the phrasing instead of piling the held
        frames at one speed (the steady circle put 73 % of the speech frames at 20-45 cm/s against the
        speaker's 29 %, most of them holds, and too few at 45-130 cm/s; 45 % and 35 % of the squared Hellinger
        distance: ``benchmarks/diag_speed_hist.py``). The radius follows the voice rather than the circle's
        angular rate: a rate must be integrated from the utterance's start, so each replan of a live stream
        that heard more moved the circle's phase under the frames playing (streamed z with 1 s of audio
        ahead fell from 2.9 to 1.1 on the questions clip of ``bench_live``, 3 seeds). Calibrated on the BEAT2
        calibration half only (``bench_generalize.py --calibration-only --no-robot --grid``, 10 seeds): at
        0.4 m/s, k = 0 / 0.3 / 0.6 / 1 gave mean z 3.48 / 3.91 / 3.76 / 3.27 and Hellinger 0.40 / 0.35 / 0.30 /
        0.31; with k = 0.6, ``drift_m_s`` 0.25 / 0.3 / 0.35 / 0.4 gave z 4.47 / 4.32 / 3.94 / 3.76, Hellinger
        0.39 / 0.36 / 0.32 / 0.30, speed 0.64 / 0.70 / 0.75 / 0.81x. Chosen then: k = 0.6 and 0.3 m/s, the
        fastest drift that kept z at 4 or more (stroke timing first); with the drift speeding up on the beats
        (``drift_beat_rad``), 0.45 m/s. (An angular rate that followed the voice had
        scored z 4.63 and Hellinger 0.29 at 0.4 m/s: part of that was the drift's own speed peaking in loud
        stretches, near stressed syllables.)
    drift_beat_rad, drift_beat_s : float
        The drift's circle turns ``drift_beat_rad`` further on each beat, over a Gaussian of ``drift_beat_s``
        (standard deviation) centred ``stroke_lead_s`` before it, and gives the turn back over the next half second
        (:data:`DRIFT_RETURN_S`): the hands' steady drift speeds up on every beat, chosen for a stroke or not, as
        a speaker's hands do, without a stroke's preparation and retraction. The turn is given back so that each
        beat changes the motion only near it: a live plan that generates from a later start, or hears one beat
        more, moves the circle's phase only around that beat (a rate integrated from the start had shifted it
        under the frames playing, see ``drift_loudness``). Calibrated on the BEAT2 calibration half only
        (``bench_generalize.py --calibration-only --no-robot``, 10 seeds, with ``drift_m_s`` 0.35-0.5,
        ``drift_beat_rad`` 0.5-0.7 and ``drift_beat_s`` 0.04-0.05: mean z 6.36-6.82 everywhere, against 4.86
        without), the value kept is the one with the highest z among those meeting the kinematic targets of
        issue 13 (speed and acceleration 0.7-1.3x the speaker's, Hellinger at most 0.3 on every seed):
        0.45 m/s, 0.5 rad, 0.05 s gave z 6.45 (worst 5.80), Hellinger 0.27 (0.28), speed 0.87x, acceleration
        1.17x (the steady 0.3 m/s drift without: 4.86 (3.98), 0.36, 0.70x, 0.81x). 0 turns it off.
    live_drift_m_s : float
        ``drift_m_s`` for the plans of a live stream, whose drift keeps the radius of mid loudness (it plans
        frames beyond the audio heard). A live plan speeds the drift up only on the beats heard or expected in
        time (see :meth:`generate`; in real time mostly the expected ones), too few to keep a faster drift's own
        speed peaks on the beat. On the BEAT2 calibration half streamed in real time (``bench_live``'s measure,
        10 seeds), with the radius following the loudness as offline: 0.45 m/s with every beat 3.86, with the
        expected beats 4.28, with none 2.80; 0.3 m/s with the expected beats 4.46 (the steady 0.3 m/s drift
        before ``drift_beat_rad``: 4.11); with the steady radius and the speed-ups of
        :data:`LIVE_DRIFT_RISE_WIDTHS`: 0.3 m/s 5.42, 0.4 m/s 5.12 (7 seeds; 5.37 at 0.3 on the same seeds).
    stroke_lead_s : float
        How far before its acoustic beat an arm stroke's wrist-speed peak is placed (preparations and
        relaxations, which also peak on beats, lead by the same amount). Gesture strokes precede the
        prosodic peak they go with: the stroke ends at, not after, the stressed syllable (McNeill 1992's
        phonological synchrony rule; Leonard & Cummins 2011 find the hand's apex at the stressed syllable),
        so its speed peak comes before the vowel onset, which is about where an acoustic beat (a loudness
        rise) lies. Tagged gestures (``^gesture(name)``) are not led: their stroke peaks on the beat of
        their word, as documented. Head moves stay on their beat. Picked by mean stroke-sync z on the BEAT2
        calibration half only (``bench_generalize.py --calibration-only --no-robot --grid``, 10 seeds):
        0 s 2.54, 0.02 s 3.44, 0.04-0.10 s a plateau of 3.76-3.97 (highest at 0.05 s), 0.12 s 3.26.
    semantic : str
        ``"keywords"`` (trigger words only) or ``"embedding"``: sentences whose words trigger no arm unit
        get the unit whose ``meaning`` is closest in MiniLM sentence embedding (needs the learn extra).
    max_joint_speed_rad_s, max_joint_accel_rad_s2 : float or None
        Speed and acceleration limits of the body that will play the motion (e.g. a robot's slowest arm
        joint), applied to every move's largest angle change, so strokes are timed for what the robot can do
        instead of being smeared by its safety layer. Not set by the pipeline: on the BEAT2 calibration half
        the humanoid's 15 rad/s² brought its z closer to the human motion's (0.89 vs 0.84 of it) but lower
        (2.4 vs 2.9), as fewer gestures fit.
    """

    fps: float | None = None
    prep_s: float = 1.2
    min_prep_s: float = 0.2
    gesture_rate: float = 2.5
    amplitude: float = 2.0
    retract_s: float = 0.5
    rest_lead_s: float = 0.35
    min_rest_span_s: float = 0.95
    ready_after_s: float = 0.8
    sway_rad: float = 0.05
    head_beat_prob: float = 0.35
    max_wrist_speed_m_s: float = 2.4
    max_wrist_accel_m_s2: float | None = 15.0
    stroke_scale: float = 1.0
    prep_speed_ratio: float = 0.7
    hold_scale: float = 0.0
    amount: float = 1.0
    gestures: str = "auto"
    max_joint_speed_rad_s: float | None = None
    max_joint_accel_rad_s2: float | None = None
    semantic: str = "keywords"
    stroke_lead_s: float = 0.05
    drift_m_s: float = 0.45
    drift_hz: float = 0.5
    drift_loudness: float = 0.6
    drift_beat_rad: float = 0.5
    drift_beat_s: float = 0.05
    live_drift_m_s: float = 0.3


#: Wrist-path entries (:meth:`RhythmGenerator._path`) kept per generator: the built-in units' pose pairs number a
#: few hundred, but a live session's late strokes start from whatever pose is held, so over hours the keys would
#: grow without end (measured: 281-906 new entries, about 0.5 KB each, per 6.6 s streamed utterance).
FK_CACHE_SIZE = 4096
#: The same unit is not used twice in a row within this many seconds.
NO_REPEAT_S = 10.0
#: Semantic units on one channel keep at least this far apart (seconds).
SEMANTIC_SPACING_S = 1.0
#: The drift gives back each beat's extra turn (``drift_beat_rad``) this long after the beat, seconds, over a
#: Gaussian of :data:`DRIFT_RETURN_WIDTH_S`; slow enough that the circle never turns backwards (0.5 rad over
#: 0.2 s is at most 1.0 rad/s against 3.1 rad/s at 0.5 Hz). Picked with the other drift values on the calibration
#: half: returning after 0.3 or 0.5 s, over 0.1 or 0.2 s, gave z 6.35-6.59 at 0.3 m/s.
DRIFT_RETURN_S = 0.3
DRIFT_RETURN_WIDTH_S = 0.2
#: Live plans: the drift speeds up on a beat when its speed-up, from this many widths (``drift_beat_s``) before its
#: peak, comes after the frames played (:meth:`LivePlan.drift_beats`). Calibrated on the BEAT2 calibration half
#: only, streamed in real time (``bench_live``'s measure, robot goals, 10 seeds), with the drift's radius then still
#: following the loudness: 0 / 1 / 3 widths gave stroke-sync z 4.22 / 4.67 / 4.46 (before, on the expected beats
#: whatever was played, and forgotten once heard: 4.46); re-checked with the live plans' steady radius: 4.66 / 5.42 /
#: 5.35.
LIVE_DRIFT_RISE_WIDTHS = 1.0
#: Gaussian smoothing (s) of the loudness the drift's speed follows: phrase-level rises, not each syllable.
LOUDNESS_SMOOTH_S = 0.3
#: Band loudness (dB) below this is digital silence (a stream's zero padding), not part of the voice's range.
DIGITAL_SILENCE_DB = -100.0
#: Live plans: a word not heard yet in which eSpeak NG stresses no syllable (most function words) is expected to
#: bring a beat this long after its start, seconds. Calibrated on the BEAT2 calibration half only, streamed at real
#: time (``bench_live.bench_sync``'s stream, 10 seeds), when every word was expected this way: 0.05 / 0.08 / 0.11 s
#: gave stroke-sync z 2.51 / 2.93 / 2.87 (the median offset of its stressed vowels from the starts of content words
#: is 0.08 s, of function words 0.03 s).
WORD_BEAT_S = 0.08
#: Live plans: a word whose stressed syllable has not been heard yet is expected to bring a beat this long after
#: that syllable's estimated onset (:func:`~robogest.speech.stress.stress_fraction` of the word's span), seconds.
#: Calibrated on the BEAT2 calibration half only, streamed at real time, 6 seeds: -0.03 / 0 / +0.03 s gave
#: stroke-sync z 3.27 / 3.51 / 3.08 (word-start beats: 2.42), with a word counted as heard 0.1 s after its
#: start; counted as heard only 0.1 s after its stressed syllable, 0 s gave 4.14 (offline 3.99).
STRESS_BEAT_S = 0.0
#: Offline, when words are known, a word's stressed syllable (:meth:`RhythmGenerator.stressed_syllable_s`) with no
#: acoustic beat within this many seconds of it is a beat too, of prominence :data:`STRESS_PROMINENCE`: the onset
#: detector misses stresses carried by pitch or length more than loudness. Calibrated on the BEAT2 calibration half
#: only (``bench_generalize.py --calibration-only --no-robot``, 10 seeds; human-motion stroke-sync z 4.32 without):
#: 0.06 / 0.12 / 0.16 / 0.2 s gave 4.66 / 4.86 / 4.59 / 4.31; prominence 0.3 / 0.5 / 0.7 gave 4.41 / 4.86 / 4.39; a
#: beat only in words with no acoustic beat at all 4.14; moving the nearest acoustic beat onto the syllable 3.76-4.00.
STRESS_NEAR_S = 0.12
STRESS_PROMINENCE = 0.5
#: Live plans: a beat within this many seconds of one a plan has already used (a started gesture, an expected beat a
#: stroke was placed on, a started drift speed-up) is taken for the same beat, heard again a little elsewhere.
SAME_BEAT_S = 0.12
#: A beat is heard about this long after it starts (a rise 0.05 s in, confirmed 0.05 s later), seconds.
HEARD_AFTER_S = 0.1
#: Live plans: a stroke seen too late for its natural length is shortened (and scaled down alike, so its peak
#: speed stays) to no less than this, seconds, or skipped.
MIN_LATE_STROKE_S = 0.1


@dataclass(frozen=True)
class GestureEvent:
    """A unit placed in time: its stroke is centred on ``t_s``."""

    t_s: float
    unit: str
    amplitude: float
    source: str  # "tag:<word>", "keyword:<trigger>", "meaning:<similarity>" or "beat"


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


@dataclass
class _Track:
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
        return kv[i] + (kv[j] - kv[i]) * w


def _words_lower(speech: Speech) -> list[str]:
    return [re.sub(r"[^a-z']", "", w.text.lower()) for w in speech.words]


@register_generator("rhythm")
class RhythmGenerator(Generator):
    """Rule-based, beat-synchronous gestures from a hand-authored lexicon; works on a fresh install."""

    name = "rhythm"

    def __init__(
        self, config: RhythmConfig | None = None, repertoire: lx.Repertoire | None = None, **overrides: float | str
    ) -> None:
        base = config or RhythmConfig()
        self.config = RhythmConfig(**{**base.__dict__, **overrides}) if overrides else base
        c = self.config
        if not 0.0 <= c.amount <= 2.0:
            raise InputError(f"gesture amount must be within [0, 2], got {c.amount}")
        if c.gestures not in ("auto", "none"):
            raise InputError(f"gestures must be 'auto' or 'none', got {c.gestures!r}")
        if c.semantic not in ("keywords", "embedding"):
            raise InputError(f"semantic must be 'keywords' or 'embedding', got {c.semantic!r}")
        if not 0.0 <= c.drift_loudness <= 1.0:
            raise InputError(f"drift_loudness must be within [0, 1], got {c.drift_loudness}")
        if not (0.0 <= c.drift_beat_rad <= 1.0 and 0.01 <= c.drift_beat_s <= 0.2):
            raise InputError(
                f"drift_beat_rad must be within [0, 1] rad and drift_beat_s within [0.01, 0.2] s, got "
                f"{c.drift_beat_rad} and {c.drift_beat_s}"
            )
        if c.max_wrist_accel_m_s2 is not None and not c.max_wrist_accel_m_s2 > 0:
            raise InputError(f"max_wrist_accel_m_s2 must be above 0 m/s² (None: no cap), got {c.max_wrist_accel_m_s2}")
        if not 0.0 <= c.stroke_lead_s <= 0.5:
            raise InputError(f"stroke_lead_s must be within [0, 0.5] s, got {c.stroke_lead_s}")
        for key in ("drift_m_s", "live_drift_m_s"):  # a wrist speed: beyond 1 m/s the drift would be a gesture
            if not 0.0 <= getattr(c, key) <= 1.0:
                raise InputError(f"{key} must be within [0, 1] m/s, got {getattr(c, key)}")
        self._meaning = None
        self.repertoire = repertoire or lx.default_repertoire()
        self._fk_cache: dict[bytes, tuple[float, float]] = {}

    # --- planning -------------------------------------------------------------------------
    def rest_windows(self, speech: Speech) -> list[tuple[float, float]]:
        """Spans ``(t0, t1)`` in which the motion is exactly the rest pose."""
        c = self.config
        out = []
        for a, b in speech.silent_spans:
            if b - a < c.min_rest_span_s and a > 1e-6:
                continue  # short pause mid-speech: hold the ready pose instead (a leading one is spent at rest)
            t0 = a if a <= 1e-6 else a + c.retract_s  # the motion starts at rest
            t1 = b if b >= speech.duration_s - 1e-6 else b - c.rest_lead_s
            if t1 > t0:
                out.append((t0, t1))
        return out

    def beats(self, speech: Speech, loudness_db: np.ndarray | None = None, stressed: bool = True) -> AcousticBeats:
        """Where strokes may land: :func:`acoustic.acoustic_beats` of the speech, outside silent periods
        (``loudness_db``: its :func:`acoustic.band_loudness_db`, if already computed), judged against the levels
        of the audio heard (:attr:`Speech.heard_s`); and if ``stressed``, the stressed syllables of the words (heard)
        with no acoustic beat within :data:`STRESS_NEAR_S`.

        A live plan passes ``stressed=False``: it expects a beat on each word's stressed syllable until that is
        heard instead (:meth:`_expected_beats`); giving heard words these beats too lowered its stroke sync
        (BEAT2 calibration half, real time, 10 seeds: 4.11 -> 3.33).
        """
        ab = acoustic_beats(
            speech.audio, speech.sr, tuple(speech.silent_spans), loudness_db=loudness_db, heard_s=speech.heard_s
        )
        upto = speech.duration_s if speech.heard_s is None else speech.heard_s - HEARD_AFTER_S
        syls = [self.stressed_syllable_s(w) for w in speech.words] if stressed else []
        extra = [s for s in syls if s is not None and 0 <= s < upto and np.all(np.abs(ab.t_s - s) >= STRESS_NEAR_S)]
        if not extra:
            return ab
        t = np.concatenate([ab.t_s, extra])
        order = np.argsort(t, kind="stable")
        return AcousticBeats(t[order], np.concatenate([ab.prominence, np.full(len(extra), STRESS_PROMINENCE)])[order])

    @staticmethod
    def stressed_syllable_s(w: Word) -> float | None:
        """Where word ``w``'s stressed syllable starts, s: its span shared among its phonemes in eSpeak NG's
        lexicon (:func:`~robogest.speech.stress.stress_fraction`) plus :data:`STRESS_BEAT_S`; None when eSpeak
        stresses none of its syllables."""
        f = stress_fraction(w.text)
        return None if f is None else w.start_s + f * (w.end_s - w.start_s) + STRESS_BEAT_S

    def _expected_beats(self, ab: AcousticBeats, speech: Speech, live: LivePlan) -> tuple[AcousticBeats, set[float]]:
        """``ab`` plus a beat on the stressed syllable (:meth:`stressed_syllable_s`; :data:`WORD_BEAT_S` after the
        start of a word in which eSpeak NG stresses no syllable) of each word that has no beat and whose syllable
        is not heard yet, and the expected beats a stroke was already placed on (replacing heard beats within
        :data:`SAME_BEAT_S` of them), of prominence :data:`STRESS_PROMINENCE` (a stressed syllable with no acoustic
        evidence yet, as offline). Also returns the expected beats, on the utterance's clock (rounded to 1 ms)."""
        off, heard = speech.offset_s, speech.heard_s
        t, p = list(ab.t_s), list(ab.prominence)
        expected = {s for s in live.expected_s if off <= s < off + speech.duration_s}
        if heard is not None:
            for w in speech.words:
                syl = self.stressed_syllable_s(w)
                heard_from, at = (w.start_s, w.start_s + WORD_BEAT_S) if syl is None else (syl, syl)
                if heard_from + HEARD_AFTER_S > heard and not any(w.start_s - 0.1 <= b <= w.end_s for b in t):
                    expected.add(round(at + off, 3))
        for e in sorted(expected):
            keep = [i for i, b in enumerate(t) if abs(b + off - e) > SAME_BEAT_S]
            t, p = [t[i] for i in keep] + [e - off], [p[i] for i in keep] + [STRESS_PROMINENCE]
        order = np.argsort(t, kind="stable")
        return AcousticBeats(np.asarray(t, float)[order], np.asarray(p, float)[order]), expected

    def plan(self, speech: Speech, seed: int = 0, acoustic: AcousticBeats | None = None) -> list[GestureEvent]:
        """Choose arm and head events (time, unit, amplitude) on acoustic beats; deterministic for a seed.

        Order of precedence: inline tags (``^gesture(name)`` in :attr:`Speech.text`), then semantic units
        by priority within each sentence (trigger words; ``"?"`` = the last word of a question), then beat
        units from the statistical interpreter on the remaining beats. A unit is not repeated back to back
        within :data:`NO_REPEAT_S`. Beat decisions are drawn beat by beat in time order, so a prefix of
        the beats (a partial utterance, as when streaming) gets the choices it gets in the whole one.
        ``acoustic`` passes :meth:`beats` already computed (each call otherwise detects them again).
        """
        c = self.config
        if c.gestures == "none" or c.amount <= 0:
            return []
        rep = self.repertoire
        rng = np.random.default_rng(seed)
        ab = acoustic if acoustic is not None else self.beats(speech)
        beats, prom = ab.t_s, ab.prominence
        amp = c.amplitude * (0.5 + 0.5 * c.amount)
        words = speech.words
        events: list[GestureEvent] = []
        taken: set[tuple[int, str]] = set()  # (beat, channel): arms and head may share a beat

        def beat_in(k: int, unit: str) -> int | None:
            w, ch = words[k], rep.units[unit].channel
            near = np.where((beats >= w.start_s - 0.1) & (beats <= w.end_s))[0]
            near = [int(i) for i in near if (int(i), ch) not in taken]
            return near[0] if near else None

        def clashes(t: float, unit: str) -> bool:
            ch = rep.units[unit].channel
            for e in events:
                if rep.units[e.unit].channel != ch:
                    continue
                if abs(e.t_s - t) < SEMANTIC_SPACING_S or (e.unit == unit and abs(e.t_s - t) < NO_REPEAT_S):
                    return True
            return False

        spoken = [w.text for w in words]
        index = align_words(speech.text, spoken) if speech.text else []
        # 1. Tags pin a unit to the next word (^run: in the pause before it, its hold ending as the word starts).
        for tag in parse_tags(speech.text) if speech.text else []:
            name = resolve_unit(tag.name, rep.units)
            if name is None:
                known = ", ".join(sorted(rep.units))
                raise InputError(f"gesture tag ^{tag.kind}({tag.name}): unknown unit; known units: {known}")
            k = index[tag.word_index] if tag.word_index < len(index) else None
            if k is None:
                continue
            u = rep.units[name]
            bi = beat_in(k, name) if tag.kind != "run" else None
            t = float(beats[bi]) if bi is not None else words[k].start_s
            t -= (u.stroke_s / 2 + u.hold_s) if tag.kind == "run" else 0.0
            p = float(prom[bi]) if bi is not None else 0.6
            if bi is not None:
                taken.add((bi, u.channel))
            events.append(GestureEvent(t, name, amp * (0.6 + 0.4 * p), f"tag:{words[k].text}"))
        # 2. Semantic units by priority within each sentence, never off an acoustic beat; none where a ^mode tag
        # says random (beats without meaning) or disabled.
        keys = rep.keywords()
        modes = mode_spans(speech.text) if speech.text else []
        plain = {k for a, b, _ in modes for k in index[a:b] if k is not None}
        for first, last in self._sentence_spans(speech, index):
            cands: list[tuple[int, int, str, str]] = []  # (-priority, word, unit, trigger)
            for k in (k for k in range(first, last + 1) if k not in plain):
                key = spoken[k]
                pair = f"{key} {spoken[k + 1]}" if k + 1 <= last else ""
                for trig in (pair, key):
                    for unit in keys.get(trig, []) if trig else []:
                        cands.append((-rep.units[unit].priority, k, unit, trig))
            if self._is_question(speech, index, last) and last not in plain:
                cands += [(-rep.units[u].priority, last, u, "?") for u in keys.get("?", [])]
            arm_picked = False
            for _, k, unit, trig in sorted(cands):
                bi = beat_in(k, unit)
                if bi is None or clashes(float(beats[bi]), unit):
                    continue
                taken.add((bi, rep.units[unit].channel))
                arm_picked |= rep.units[unit].channel == "arms"
                p = float(prom[bi])
                events.append(GestureEvent(float(beats[bi]), unit, amp * (0.6 + 0.4 * p), f"keyword:{trig}"))
            if c.semantic == "embedding" and not arm_picked and first not in plain:
                self._by_meaning(spoken[first : last + 1], words[first].start_s, words[last].end_s, beats, prom,
                                 taken, clashes, events, amp)  # fmt: skip
        semantic_arms = np.array(sorted(e.t_s for e in events if rep.units[e.unit].channel == "arms"))
        # 3. Ordinary beats: the statistical interpreter picks beat units; some beats get head beats.
        names = rep.beat_units
        counts = np.zeros(len(names))
        prev: tuple[float, str] | None = None
        for bi, (t, p) in enumerate(zip(beats, prom, strict=True)):
            r_arm, r_head = rng.random(), rng.random()  # always two draws per beat: prefix-stable
            near_semantic = semantic_arms.size and np.any((semantic_arms - t < 0.8) & (t - semantic_arms < 0.5))
            if (
                names
                and (bi, "arms") not in taken
                and not near_semantic
                and r_arm < c.amount * c.gesture_rate * (0.35 + 0.65 * p)
            ):
                avoid = frozenset([prev[1]]) if prev is not None and t - prev[0] < NO_REPEAT_S else frozenset()
                k = rep.next_beat_unit(counts, float(p), rng, avoid)
                counts[k] += 1
                prev = (float(t), names[k])
                events.append(GestureEvent(float(t), names[k], amp * (0.45 + 0.55 * p), "beat"))
            if (bi, "head") not in taken and p > 0.5 and r_head < c.head_beat_prob * p and "head_beat" in rep.units:
                events.append(GestureEvent(float(t), "head_beat", amp * p, "beat"))
        events.sort(key=lambda e: (e.t_s, e.source == "beat"))
        return events

    def _by_meaning(self, sentence, t0, t1, beats, prom, taken, clashes, events, amp) -> None:
        """Sentence-embedding choice (learn extra): the unit whose meaning is closest, on the sentence's most
        prominent free beat."""
        if self._meaning is None:
            from robogest.generators.meaning import MeaningChooser

            self._meaning = MeaningChooser(self.repertoire)
        pick = self._meaning.choose(list(sentence))
        if pick is None:
            return
        unit = pick[0]
        idx = [int(i) for i in np.where((beats >= t0 - 0.05) & (beats <= t1))[0] if (int(i), "arms") not in taken]
        for bi in sorted(idx, key=lambda i: -prom[i]):
            if not clashes(float(beats[bi]), unit):
                taken.add((bi, "arms"))
                p = float(prom[bi])
                events.append(GestureEvent(float(beats[bi]), unit, amp * (0.6 + 0.4 * p), f"meaning:{pick[1]:.2f}"))
                return

    @staticmethod
    def _sentence_spans(speech: Speech, index: list[int | None]) -> list[tuple[int, int]]:
        """Sentences as spoken-word index ranges: from the text's punctuation when it lines up with the
        words, else split at pauses of 0.3 s or more between words."""
        n = len(speech.words)
        spans: list[tuple[int, int]] = []
        if speech.text and index:
            for first, last, _ in sentences(speech.text):
                ks = [k for k in index[first : last + 1] if k is not None]
                if ks:
                    spans.append((min(ks), max(ks)))
            if spans:
                return spans
        start = 0
        for k in range(1, n + 1):
            if k == n or speech.words[k].start_s - speech.words[k - 1].end_s >= 0.3:
                spans.append((start, k - 1))
                start = k
        return spans

    @staticmethod
    def _is_question(speech: Speech, index: list[int | None], last: int) -> bool:
        if not speech.text or not index:
            return False
        return any(end == "?" and index[lw] == last for _, lw, end in sentences(speech.text) if lw < len(index))

    # --- synthesis ------------------------------------------------------------------------
    def _path(self, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        """Wrist path of a minimum-jerk move from pose ``a`` to ``b``: the steepest stretch (wrist metres per
        unit of blend) and the fraction of the move's duration at which the faster wrist peaks.

        Poses blend linearly in angle space, so the wrists move on curves whose speed peak is not always at
        the middle of the move; placing a stroke by this fraction puts its real speed peak on the beat.
        """
        key = a.tobytes() + b.tobytes()
        if key not in self._fk_cache:
            if len(self._fk_cache) >= FK_CACHE_SIZE:  # a live session's late strokes start anywhere: keep it bounded
                self._fk_cache.pop(next(iter(self._fk_cache)))  # the oldest entry
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
            self._fk_cache[key] = (float(rate.max()), frac)
        return self._fk_cache[key]

    def _min_time_s(self, a: np.ndarray, b: np.ndarray) -> float:
        """Shortest minimum-jerk move from pose ``a`` to ``b`` whose wrist speed stays under the cap (the
        path's steepest stretch times the quintic's peak rate 1.875 / T) and, with ``max_wrist_accel_m_s2``,
        whose wrist acceleration stays under that (its peak 5.77 / T² times the same stretch)."""
        c = self.config
        rate = self._path(a, b)[0]
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

    def _prep_beat(
        self, beats_s: np.ndarray, free_s: float, s0: float, need_s: float, frac: float
    ) -> tuple[float, float] | None:
        """A beat ``b`` before ``s0`` on which a preparation ending at ``s0`` can peak (its speed peak is at
        ``frac`` of its duration ``d = (s0 - b) / (1 - frac)``): at least ``need_s`` long, starting no earlier
        than ``free_s`` and within ``prep_s``. Of those, the one that best fills ``[free_s, s0]``: the
        preparation flows out of the previous gesture rather than leaving the arms parked.
        Returns ``(beat, start)``."""
        c = self.config
        frac = min(max(frac, 0.2), 0.8)
        d = (s0 - beats_s) / (1.0 - frac)
        start = s0 - d
        ok = (beats_s < s0) & (d >= need_s - 1e-9) & (s0 - beats_s <= c.prep_s) & (start >= free_s - 1e-9)
        if not ok.any():
            return None
        k = int(np.argmin(np.where(ok, start - free_s, np.inf)))
        return float(beats_s[k]), float(start[k])

    def _relax_beat(self, tr: _Track, beats_s: np.ndarray, before_s: float) -> tuple[float, float] | None:
        """In a long gap, the free beat on which to settle into READY with a slow move centred on it (its peak on
        the beat) and the move's half length, seconds; None if none fits."""
        half = max(0.35, self._min_time_s(tr.last_v, READY) / self.config.prep_speed_ratio / 2)
        ok = (beats_s - half >= tr.last_t) & (beats_s + half <= before_s)
        return (float(beats_s[ok][0]), half) if ok.any() else None

    def stroke_peak_s(self, e: GestureEvent) -> float:
        """Where the wrist-speed peak of arm event ``e``'s stroke is placed, s: ``stroke_lead_s`` before its
        beat, or on it for a tagged gesture (pinned to its word)."""
        return e.t_s if e.source.startswith("tag:") else e.t_s - self.config.stroke_lead_s

    def _arm_track(
        self,
        events: list[GestureEvent],
        rests: list[tuple[float, float]],
        end_s: float,
        beats_s: np.ndarray,
        live: LivePlan | None = None,
        off_s: float = 0.0,
        expected_s: frozenset[float] = frozenset(),
    ) -> tuple[_Track, list[tuple[float, float, GestureEvent]]]:
        """Arm/spine keyframes: each gesture is prep -> stroke (peak ``stroke_lead_s`` before its beat, see
        :meth:`stroke_peak_s`) -> hold. Every move made while speaking peaks ``stroke_lead_s`` before an
        acoustic beat (preparations and relaxations are slower than strokes);
        where speech goes on without a chosen beat the pose is held; in rest windows the arms sit exactly
        at REST (the retraction starts when the pause does). Also returns the placed strokes
        ``(start_s, end_s, event)``. ``live``: a streaming plan (:class:`LivePlan`; ``off_s`` is the speech's
        offset on the utterance's clock, ``expected_s`` the expected beats of this plan there)."""
        c = self.config
        placed: list[tuple[float, float, GestureEvent]] = []
        tr = _Track()
        tr.add(0.0, REST)
        arm = [e for e in events if self.repertoire.units[e.unit].channel == "arms"]
        units = self.repertoire.units
        moves_s = beats_s - c.stroke_lead_s  # where preparations and relaxations peak (s)
        items: list[tuple[float, str, object]] = [
            (self.stroke_peak_s(e) - units[e.unit].stroke_s / 2, "event", e) for e in arm
        ]
        items += [(r0, "rest", (r0, r1)) for r0, r1 in rests]
        items.sort(key=lambda x: (x[0], x[1] != "rest"))
        for _, kind, obj in items:
            if kind == "rest":
                r0, r1 = obj  # type: ignore[misc]
                if r0 > tr.last_t:
                    tr.add(max(tr.last_t, r0 - max(c.retract_s, self._min_time_s(tr.last_v, REST))), tr.last_v)
                tr.add(r0, REST)
                tr.add(r1, REST)
                continue
            e: GestureEvent = obj  # type: ignore[assignment]
            u = self.repertoire.units[e.unit]
            prep_pose = READY + e.amplitude * u.prep
            stroke_pose = READY + e.amplitude * u.stroke
            stroke_s = max(c.stroke_scale * u.stroke_s, self._min_time_s(prep_pose, stroke_pose))
            f_s = self._path(prep_pose, stroke_pose)[1]
            pk = self.stroke_peak_s(e)
            s0, s1 = pk - f_s * stroke_s, pk + (1 - f_s) * stroke_s
            hold_end = s1 + c.hold_scale * u.hold_s
            nxt = [r0 for r0, _ in rests if r0 > tr.last_t]
            if s0 < tr.last_t + 1e-6:
                continue  # still busy with the previous gesture
            if nxt and hold_end + max(c.retract_s, self._min_time_s(stroke_pose, REST)) > nxt[0]:
                continue  # it would run into a rest period
            relax = (
                self._relax_beat(tr, moves_s, s0 - c.prep_s)
                if s0 - tr.last_t > c.ready_after_s + 2 * c.prep_s
                else None
            )
            # Preparation: a slower move into the prep pose whose speed peak leads an earlier acoustic beat,
            # so it never adds a peak off the beat. Without such a beat the stroke starts from the held pose.
            need = max(c.min_prep_s, self._min_time_s(tr.last_v, prep_pose) / c.prep_speed_ratio)
            late = live.placed.get((round(e.t_s + off_s, 2), e.unit)) if live is not None else 0.0
            prep = None
            if late is None or late == 0.0:  # as offline: relax if the gap is long, then prepare on an earlier beat
                held_t, held_v = (relax[0] + relax[1], READY) if relax else (tr.last_t, tr.last_v)
                prep = self._prep_beat(moves_s, held_t, s0, need, self._path(held_v, prep_pose)[1])
                move = relax[0] - relax[1] if relax else (s0 if prep is None else prep[1])  # the motion's start
                if late is None:  # first seen by this live plan: too late for its preparation (or relaxation)?
                    late = 0.0 if move >= live.commit_s - off_s - 1e-6 else -1.0  # type: ignore[union-attr]
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
                d = max(stroke_s, self._min_time_s(tr.last_v, stroke_pose))
                f_d = self._path(tr.last_v, stroke_pose)[1]
                if late < 0:
                    lo = max(tr.last_t, live.commit_s - off_s)  # type: ignore[union-attr]
                    late = min(1.0, (pk - lo - 0.01) / (f_d * d))
                    if late * d < MIN_LATE_STROKE_S:
                        continue
                if late > 0:
                    stroke_pose = tr.last_v + (stroke_pose - tr.last_v) * late  # same peak speed, shorter
                    d *= late
                s0, s1 = pk - f_d * d, pk + (1 - f_d) * d
                hold_end = s1 + c.hold_scale * u.hold_s
                if s0 < tr.last_t + 1e-6:
                    continue  # no time for the stroke at a natural speed
                if nxt and hold_end + max(c.retract_s, self._min_time_s(stroke_pose, REST)) > nxt[0]:
                    continue
                tr.add(s0, tr.last_v)
                tr.add(s1, stroke_pose)
                if late != 0.0 or not relax:  # else the motion starts with the relaxation
                    move = s0
            if live is not None:
                live.note(dataclasses.replace(e, t_s=e.t_s + off_s), late, move + off_s, s0 + off_s, expected_s)
            placed.append((s0, s1, e))
            tr.add(hold_end, stroke_pose)
        if not rests or rests[-1][1] < end_s - 1e-6:
            tr.add(max(tr.last_t, end_s - max(c.retract_s, self._min_time_s(tr.last_v, REST))), tr.last_v)
            tr.add(max(tr.last_t + 0.05, end_s), REST)
        return tr, placed

    def strokes(self, speech: Speech, seed: int = 0) -> list[tuple[float, float, GestureEvent]]:
        """The arm strokes :meth:`generate` makes: ``(start_s, end_s, event)``, speed peak at
        :meth:`stroke_peak_s` of the event (``stroke_lead_s`` before ``event.t_s``, on it for tags)."""
        ab = self.beats(speech)
        return self._arm_track(self.plan(speech, seed, ab), self.rest_windows(speech), speech.duration_s, ab.t_s)[1]

    def _head_track(self, events: list[GestureEvent], rests: list[tuple[float, float]]) -> tuple[_Track, list]:
        tr = _Track()
        zero = np.zeros(len(HEAD_DOFS))
        tr.add(0.0, zero)
        shakes: list[tuple[float, float, float, float]] = []
        busy_until = 0.0
        for e in events:
            u = self.repertoire.units[e.unit]
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
            arms = {n for n, u in self.repertoire.units.items() if u.channel == "arms"}
            events = live.keep_started(events, arms, speech.offset_s, speech.offset_s + speech.duration_s)
        beats = ab.t_s
        track = self._arm_track(events, rests, speech.duration_s, beats, live, speech.offset_s, frozenset(expected))
        dofs = track[0].sample(t)  # (T, D)
        head, shakes = self._head_track(events, rests)
        dofs[:, list(HEAD_DOFS)] += head.sample(t)
        for s0, s1, hz, amp in shakes:
            inside = (t >= s0) & (t <= s1)
            ph = (t[inside] - s0) / (s1 - s0)
            dofs[inside, DOF["head_yaw"]] += amp * np.sin(2 * np.pi * hz * (t[inside] - s0)) * np.sin(np.pi * ph) ** 2
        # A live plan speeds the drift up only on the beats whose speed-up rises (from one width before its
        # peak) after the frames played (:meth:`LivePlan.drift_beats`, :data:`LIVE_DRIFT_RISE_WIDTHS`). In real
        # time that leaves the beats it expects (stressed syllables of words that have started): an acoustic
        # beat is heard about 0.15 s before the frames that must move for it, too late. Audio delivered faster
        # than real time is heard in time.
        if live is None:
            drift_beats = beats
        else:
            rise_s = c.stroke_lead_s + LIVE_DRIFT_RISE_WIDTHS * c.drift_beat_s
            drift_beats = live.drift_beats(beats + speech.offset_s, rise_s) - speech.offset_s
        rng = np.random.default_rng(seed + 7919)
        drift_m_s = c.drift_m_s if live is None else c.live_drift_m_s
        # A live plan's drift keeps a steady radius (that of mid loudness): it plans frames up to 0.6 s beyond the
        # audio heard, so a radius that followed the loudness was rewritten under the frames about to play at
        # each plan, and each rewrite put a speed bump off the beats (see ``live_drift_m_s``).
        loud = self._loudness(db, t) if live is None else np.full(n, 0.5)
        dofs += self._sway(t, rests, rng, loud, speech.offset_s, drift_beats, drift_m_s)
        rot = dofs_to_rotations(dofs)
        root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (n, 1))
        return HumanMotion(fps=fps, rotations=rot, root_pos_m=root)

    @staticmethod
    def _loudness(db: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The voice's loudness at ``t (T,)`` s, ``(T,)`` in [0, 1], from its band loudness ``db (F,)``
        (:func:`acoustic.band_loudness_db`): smoothed over :data:`LOUDNESS_SMOOTH_S`, 0 at its 20th and 1 at its
        95th percentile over the frames that are not digital silence (those count as quiet; zeros for too short
        audio)."""
        heard = db > DIGITAL_SILENCE_DB  # not digital silence (e.g. the zeros a stream pads unheard speech with)
        if heard.sum() < 5:
            return np.zeros(len(t))
        db = gaussian_filter1d(np.where(heard, db, np.percentile(db[heard], 20)), LOUDNESS_SMOOTH_S / HOP_S)
        lo, hi = np.percentile(db[heard], 20), np.percentile(db[heard], 95)
        loud = np.clip((db - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
        return np.interp(t, np.arange(db.size) * HOP_S, loud)

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
        """Idle breathing/sway ``(T, D)`` while speaking: fades in over 0.4 s away from rest, and is
        exactly zero inside rest windows and at both ends (the motion starts and ends at rest). ``loud (T,)``
        in [0, 1] is the voice's loudness, which the wrist drift's speed follows (``drift_loudness``); the drift
        also speeds up on each of ``beats_s (B,)``, seconds on ``t``'s clock (``drift_beat_rad``), and runs at
        ``drift_m_s`` (the config's, or ``live_drift_m_s`` for a live plan). Phases run
        on the utterance's clock (``t + t0_s``, ``t0_s`` = :attr:`Speech.offset_s`), so a streaming planner that
        generates from a later start gets the same sway where the two overlap."""
        end = t[-1] if len(t) else 0.0
        d = np.minimum(t, end - t)  # (T,) distance to the ends, s
        for r0, r1 in rests:
            d = np.minimum(d, np.clip(np.maximum(r0 - t, t - r1), 0, None))
        s = np.clip(d / 0.4, 0, 1)
        env = s**3 * (10 - 15 * s + 6 * s**2)  # (T,) minimum-jerk fade
        ph = rng.uniform(0, 2 * np.pi, 8)
        a = self.config.sway_rad
        out = np.zeros((len(t), N_DOF))
        ta = t + t0_s  # (T,) s on the utterance's clock
        out[:, DOF["spine_pitch"]] = 0.6 * a * np.sin(2 * np.pi * 0.23 * ta + ph[0])
        out[:, DOF["spine_yaw"]] = a * np.sin(2 * np.pi * 0.17 * ta + ph[1])
        out[:, DOF["head_pitch"]] = 0.5 * a * np.sin(2 * np.pi * 0.31 * ta + ph[2])
        out[:, DOF["head_yaw"]] = 0.8 * a * np.sin(2 * np.pi * 0.13 * ta + ph[3])
        # The hands never freeze while speaking. Each wrist circles slowly (elbow up/down and arm out/in in
        # quadrature, levers ~0.27 m and ~0.4 m). At a steady angular rate a circle has a steady speed and no
        # speed peaks of its own that could land off the beats; with drift_loudness its radius (so its speed)
        # rises and falls with the voice's smoothed loudness, so what peaks it has lie in loud stretches. The
        # radius, not the angular rate, follows the voice: a rate would have to be integrated from the start,
        # so every replan of a stream that heard more would shift the circle's phase under the frames playing.
        c = self.config
        w = 2 * np.pi * c.drift_hz
        r = 0.0 if c.gestures == "none" else drift_m_s * c.amount / w  # circle radius, m (scales with amount)
        size = 1.0 - c.drift_loudness + 2.0 * c.drift_loudness * loud  # (T,) radius scale
        theta = w * ta
        if c.drift_beat_rad > 0:
            theta = theta + c.drift_beat_rad * self._beat_turns(t, np.asarray(beats_s) - c.stroke_lead_s)
        for k, side in enumerate("lr"):
            out[:, DOF[f"{side}_elbow"]] = r / 0.27 * size * np.sin(theta + ph[4 + 2 * k])
            out[:, DOF[f"{side}_abd"]] = r / 0.40 * size * np.cos(theta + ph[4 + 2 * k])
        return out * env[:, None]

    def _beat_turns(self, t: np.ndarray, peaks_s: np.ndarray) -> np.ndarray:
        """``(T,)``: how many beat turns the drift is ahead at ``t (T,)`` s: each peak in ``peaks_s (B,)`` adds one,
        rising over a Gaussian of ``drift_beat_s`` centred on it, and takes it back :data:`DRIFT_RETURN_S` later
        (see ``drift_beat_rad``); zero more than six widths from every beat."""
        sd = self.config.drift_beat_s
        out = np.zeros(len(t))
        lo = np.searchsorted(t, peaks_s - 6 * sd)
        hi = np.searchsorted(t, peaks_s + DRIFT_RETURN_S + 6 * DRIFT_RETURN_WIDTH_S)
        for p, i, j in zip(peaks_s, lo, hi, strict=True):
            u = t[i:j] - p
            out[i:j] += ndtr(u / sd) - ndtr((u - DRIFT_RETURN_S) / DRIFT_RETURN_WIDTH_S)
        return out
