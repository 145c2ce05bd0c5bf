"""Unit choice: which gesture unit goes on which beat (inline tags, then trigger words or meaning, then the
statistical interpreter on the remaining beats)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.generators import lexicon as lx
from robogest.generators.acoustic import AcousticBeats
from robogest.generators.animated_speech import resolve_unit
from robogest.generators.rhythm.config import RhythmConfig
from robogest.generators.tags import align_words, mode_spans, parse_tags, sentences
from robogest.speech.types import Speech

if TYPE_CHECKING:
    from robogest.generators.meaning import MeaningChooser

#: The same unit is not used twice in a row within this many seconds.
NO_REPEAT_S = 10.0
#: Semantic units on one channel keep at least this far apart (seconds).
SEMANTIC_SPACING_S = 1.0


@dataclass(frozen=True)
class GestureEvent:
    """A unit placed in time: its stroke is centred on ``t_s``."""

    t_s: float
    unit: str
    amplitude: float
    source: str  # "tag:<word>", "keyword:<trigger>", "meaning:<similarity>" or "beat"


def choose_units(
    c: RhythmConfig,
    rep: lx.Repertoire,
    speech: Speech,
    ab: AcousticBeats,
    seed: int,
    meaning: Callable[[], MeaningChooser],
) -> list[GestureEvent]:
    """Arm and head events on the beats ``ab`` of ``speech``, sorted by time (see :meth:`RhythmGenerator.plan`);
    ``meaning`` gives the sentence-embedding chooser, called only with ``semantic="embedding"``."""
    rng = np.random.default_rng(seed)
    ch = _Chooser(c, rep, speech, ab)
    index = align_words(speech.text, ch.spoken) if speech.text else []
    ch.tags(index)
    ch.semantic(index, meaning)
    ch.beat_units(rng)
    ch.events.sort(key=lambda e: (e.t_s, e.source == "beat"))
    return ch.events


class _Chooser:
    """The events chosen so far and the beats they took, per channel (arms and head may share a beat)."""

    def __init__(self, c: RhythmConfig, rep: lx.Repertoire, speech: Speech, ab: AcousticBeats) -> None:
        self.c, self.rep, self.speech = c, rep, speech
        self.beats, self.prom = ab.t_s, ab.prominence  # (B,) s, (B,)
        self.amp = c.amplitude * (0.5 + 0.5 * c.amount)
        self.words = speech.words
        self.spoken = [w.text for w in speech.words]
        self.events: list[GestureEvent] = []
        self.taken: set[tuple[int, str]] = set()  # (beat, channel)

    def beat_in(self, k: int, unit: str) -> int | None:
        """The first beat free on ``unit``'s channel within word ``k`` (from 0.1 s before it starts)."""
        w, ch = self.words[k], self.rep.units[unit].channel
        near = np.where((self.beats >= w.start_s - 0.1) & (self.beats <= w.end_s))[0]
        free = [int(i) for i in near if (int(i), ch) not in self.taken]
        return free[0] if free else None

    def clashes(self, t: float, unit: str) -> bool:
        """Whether ``unit`` at ``t`` s comes too close to an event on its channel (or repeats the unit)."""
        ch = self.rep.units[unit].channel
        for e in self.events:
            if self.rep.units[e.unit].channel != ch:
                continue
            if abs(e.t_s - t) < SEMANTIC_SPACING_S or (e.unit == unit and abs(e.t_s - t) < NO_REPEAT_S):
                return True
        return False

    def add(self, bi: int, unit: str, source: str) -> None:
        """Put ``unit`` on beat ``bi`` (a semantic choice: its size follows the beat's prominence)."""
        self.taken.add((bi, self.rep.units[unit].channel))
        p = float(self.prom[bi])
        self.events.append(GestureEvent(float(self.beats[bi]), unit, self.amp * (0.6 + 0.4 * p), source))

    def tags(self, index: list[int | None]) -> None:
        """1. Tags (``^gesture(name)``, ``^start``, ``^run``: docs/animated-speech.md) pin a unit to the next word: on
        its first free beat, else its start; ``^run``'s in the pause before the word, its hold ending as it starts."""
        rep, words = self.rep, self.words
        for tag in parse_tags(self.speech.text) if self.speech.text else []:
            name = resolve_unit(tag.name, rep.units)
            if name is None:
                known = ", ".join(sorted(rep.units))
                raise InputError(f"gesture tag ^{tag.kind}({tag.name}): unknown unit; known units: {known}")
            k = index[tag.word_index] if tag.word_index < len(index) else None
            if k is None:
                continue
            u = rep.units[name]
            bi = self.beat_in(k, name) if tag.kind != "run" else None
            source = f"tag:{words[k].text}"
            if bi is not None:
                self.add(bi, name, source)
            else:  # no free beat in the word (or ^run): before its start, at a middling prominence (0.6)
                t = words[k].start_s - ((u.stroke_s / 2 + u.hold_s) if tag.kind == "run" else 0.0)
                self.events.append(GestureEvent(t, name, self.amp * (0.6 + 0.4 * 0.6), source))

    def semantic(self, index: list[int | None], meaning: Callable[[], MeaningChooser]) -> None:
        """2. Semantic units by priority within each sentence, never off an acoustic beat; none where a ``^mode``
        tag says random (beats without meaning) or disabled."""
        keys = self.rep.keywords()
        modes = mode_spans(self.speech.text) if self.speech.text else []
        plain = {k for a, b, _ in modes for k in index[a:b] if k is not None}
        for first, last in sentence_spans(self.speech, index):
            arm_picked = False
            for _, k, unit, trig in sorted(self._candidates(keys, index, first, last, plain)):
                bi = self.beat_in(k, unit)
                if bi is None or self.clashes(float(self.beats[bi]), unit):
                    continue
                arm_picked |= self.rep.units[unit].channel == "arms"
                self.add(bi, unit, f"keyword:{trig}")
            if self.c.semantic == "embedding" and not arm_picked and first not in plain:
                self.by_meaning(first, last, meaning())

    def _candidates(
        self, keys: dict[str, list[str]], index: list[int | None], first: int, last: int, plain: set[int]
    ) -> list[tuple[int, int, str, str]]:
        """``(-priority, word, unit, trigger)`` for the trigger words (and word pairs, ``keys``: trigger -> units)
        of words ``first..last`` outside ``plain`` (``^mode`` random/disabled); ``"?"`` triggers on the last word of
        a question."""
        rep, spoken = self.rep, self.spoken
        cands: list[tuple[int, int, str, str]] = []
        for k in (k for k in range(first, last + 1) if k not in plain):
            key = spoken[k]
            pair = f"{key} {spoken[k + 1]}" if k + 1 <= last else ""
            for trig in (pair, key):
                for unit in keys.get(trig, []) if trig else []:
                    cands.append((-rep.units[unit].priority, k, unit, trig))
        if is_question(self.speech, index, last) and last not in plain:
            cands += [(-rep.units[u].priority, last, u, "?") for u in keys.get("?", [])]
        return cands

    def by_meaning(self, first: int, last: int, chooser: MeaningChooser) -> None:
        """Sentence-embedding choice (learn extra): the unit whose meaning is closest, on the sentence's most
        prominent free beat."""
        pick = chooser.choose(list(self.spoken[first : last + 1]))
        if pick is None:
            return
        unit = pick[0]
        t0, t1 = self.words[first].start_s, self.words[last].end_s
        free = np.where((self.beats >= t0 - 0.05) & (self.beats <= t1))[0]
        idx = [int(i) for i in free if (int(i), "arms") not in self.taken]
        for bi in sorted(idx, key=lambda i: -self.prom[i]):
            if not self.clashes(float(self.beats[bi]), unit):
                self.taken.add((bi, "arms"))
                p = float(self.prom[bi])
                source = f"meaning:{pick[1]:.2f}"
                self.events.append(GestureEvent(float(self.beats[bi]), unit, self.amp * (0.6 + 0.4 * p), source))
                return

    def beat_units(self, rng: np.random.Generator) -> None:
        """3. Ordinary beats: the statistical interpreter picks beat units; some beats get head beats. Two draws
        per beat in time order, so a prefix of the beats (a partial utterance) gets the choices of the whole."""
        c, rep = self.c, self.rep
        semantic_arms = np.array(sorted(e.t_s for e in self.events if rep.units[e.unit].channel == "arms"))
        names = rep.beat_units
        counts = np.zeros(len(names))
        prev: tuple[float, str] | None = None
        for bi, (t, p) in enumerate(zip(self.beats, self.prom, strict=True)):
            r_arm, r_head = rng.random(), rng.random()  # always two draws per beat: prefix-stable
            near_semantic = semantic_arms.size and np.any((semantic_arms - t < 0.8) & (t - semantic_arms < 0.5))
            if (
                names
                and (bi, "arms") not in self.taken
                and not near_semantic
                and r_arm < c.amount * c.gesture_rate * (0.35 + 0.65 * p)
            ):
                avoid = frozenset([prev[1]]) if prev is not None and t - prev[0] < NO_REPEAT_S else frozenset()
                k = rep.next_beat_unit(counts, float(p), rng, avoid)
                counts[k] += 1
                prev = (float(t), names[k])
                self.events.append(GestureEvent(float(t), names[k], self.amp * (0.45 + 0.55 * p), "beat"))
            head_free = (bi, "head") not in self.taken and p > 0.5
            if head_free and r_head < c.head_beat_prob * p and "head_beat" in rep.units:
                self.events.append(GestureEvent(float(t), "head_beat", self.amp * p, "beat"))


def sentence_spans(speech: Speech, index: list[int | None]) -> list[tuple[int, int]]:
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


def is_question(speech: Speech, index: list[int | None], last: int) -> bool:
    """Whether the sentence ending at spoken word ``last`` ends with a question mark."""
    if not speech.text or not index:
        return False
    return any(end == "?" and index[lw] == last for _, lw, end in sentences(speech.text) if lw < len(index))
