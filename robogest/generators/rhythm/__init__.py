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

The package's modules, in pipeline order: :mod:`.config` (:class:`RhythmConfig`), :mod:`.beats` (where strokes may
land, where the motion rests), :mod:`.units` (which unit on which beat), :mod:`.timeline` and :mod:`.arms`
(minimum-jerk keyframe tracks), :mod:`.drift` (idle sway and wrist drift), :mod:`.live` (:class:`LivePlan`) and
:mod:`.generator`, which composes them (:class:`RhythmGenerator`, registered as ``"rhythm"``).
"""

from robogest.generators.rhythm.beats import HEARD_AFTER_S, STRESS_BEAT_S, STRESS_NEAR_S, STRESS_PROMINENCE
from robogest.generators.rhythm.config import RhythmConfig
from robogest.generators.rhythm.drift import (
    DIGITAL_SILENCE_DB,
    DRIFT_RETURN_S,
    DRIFT_RETURN_WIDTH_S,
    LOUDNESS_SMOOTH_S,
)
from robogest.generators.rhythm.generator import RhythmGenerator
from robogest.generators.rhythm.live import (
    LIVE_DRIFT_RISE_WIDTHS,
    MIN_LATE_STROKE_S,
    SAME_BEAT_S,
    WORD_BEAT_S,
    LivePlan,
)
from robogest.generators.rhythm.timeline import FK_CACHE_SIZE
from robogest.generators.rhythm.units import NO_REPEAT_S, SEMANTIC_SPACING_S, GestureEvent

__all__ = [
    "DIGITAL_SILENCE_DB",
    "DRIFT_RETURN_S",
    "DRIFT_RETURN_WIDTH_S",
    "FK_CACHE_SIZE",
    "HEARD_AFTER_S",
    "LIVE_DRIFT_RISE_WIDTHS",
    "LOUDNESS_SMOOTH_S",
    "MIN_LATE_STROKE_S",
    "NO_REPEAT_S",
    "SAME_BEAT_S",
    "SEMANTIC_SPACING_S",
    "STRESS_BEAT_S",
    "STRESS_NEAR_S",
    "STRESS_PROMINENCE",
    "WORD_BEAT_S",
    "GestureEvent",
    "LivePlan",
    "RhythmConfig",
    "RhythmGenerator",
]
