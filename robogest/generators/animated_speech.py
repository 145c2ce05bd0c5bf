"""NAOqi ALAnimatedSpeech scripts: text with ``^start``/``^wait``/``^stop``/``^run``/``^mode`` tags and the TTS's
``\\pau=MS\\``, ``\\rspd=N\\``, ``\\rst\\``, spoken with eSpeak NG; semantics and the NAOqi name table in
docs/animated-speech.md.

The tags shape the speech (pauses, rate) here; the gesture pins and modes stay in :attr:`Speech.text` for the
generator (:mod:`robogest.generators.tags`), and the silent periods are set so the robot rests in ``\\pau`` pauses
and ``^mode(disabled)`` stretches (the silent-period hint) but holds its gesture while speech waits for one.
"""

from __future__ import annotations

import dataclasses
import logging
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

from robogest.errors import InputError
from robogest.generators.tags import (
    MODES,
    PIN_KINDS,
    Found,
    _tokens,
    align_words,
    mode_spans,
    parse_tags,
    scan,
    strip_tags,
    word_index_at,
)
from robogest.speech.core import TextSegment
from robogest.speech.types import Speech

log = logging.getLogger(__name__)

#: NAOqi animation names (``animations/Stand/Gestures/<Name>_<n>``; the ``_<n>`` variant dropped) -> our unit,
#: where one means the same. A gesture file unit named like the animation (``Hey_1``) takes precedence.
NAOQI_UNITS: dict[str, str] = {
    "Explain": "palms_up_open",
    "YouKnowWhat": "point_forward",
    "You": "point_forward",
    "Me": "self_point",
    "ShowSky": "point_away",
    "ShowFloor": "point_away",
    "Far": "point_away",
    "Everything": "spread_both",
    "Enthusiastic": "spread_both",
    "This": "frame_both",
    "Give": "offer_r",
    "Please": "offer_r",
    "No": "negation_sweep",
    "Nothing": "negation_sweep",
    "Yes": "nod",
    "IDontKnow": "shrug",
    "Thinking": "head_tilt",
    "BodyTalk": "beat_medium_both",
}
#: Preparation allowed before a ``^run`` unit's stroke, s (its pause: this + stroke + hold).
RUN_PREP_S = 0.4
#: ``^wait``: speech resumes this long after the started unit's nominal end (its stroke may land late in its word).
WAIT_MARGIN_S = 0.3
#: Around a gesture pinned inside a ``^mode(disabled)`` stretch the robot does not rest: s before and after its word.
PIN_CLEAR_S = (1.0, 1.2)
#: Leftovers of a silent period shorter than this (s) are dropped when a pause in which speech waits is cut out.
MIN_SPAN_S = 0.05
RSPD_PERCENT = (50, 200)  # Acapela's range for \rspd
MAX_PAUSE_MS = 10000
_BREAKS = ("pau", "rspd", "rst", "wait", "run")
_KNOWN = "^gesture, ^start, ^wait, ^stop, ^run, ^mode, \\pau, \\rspd, \\rst"


def resolve_unit(name: str, units: Collection[str]) -> str | None:
    """The unit ``name`` stands for: itself, its last path part (``animations/Stand/Gestures/Hey_1`` -> ``Hey_1``),
    that without its ``_<n>`` variant (``Hey``), or the unit :data:`NAOQI_UNITS` gives; None if none is in
    ``units``."""
    base = name.rsplit("/", 1)[-1]
    stem = re.sub(r"_\d+$", "", base)
    for cand in (name, base, stem, NAOQI_UNITS.get(stem)):
        if cand and cand in units:
            return cand
    return None


@dataclass(frozen=True)
class Script:
    """An annotated text, checked: ``text`` keeps the tags the generator reads (those dropped removed);
    ``segments`` are what eSpeak speaks, ``pause_kinds`` why each one's pause is there (``"rest"``: ``\\pau``;
    ``"hold"``: speech waits for a gesture; ``""``: none); ``dropped`` the tags left out (``lenient``)."""

    text: str
    segments: tuple[TextSegment, ...]
    pause_kinds: tuple[str, ...]
    dropped: tuple[str, ...] = ()

    def plain(self, words_per_minute: int) -> bool:
        """One piece at the call's rate with no pause: spoken by :func:`robogest.speech.synthesize` as is."""
        (s, *more) = self.segments
        return not more and not s.pause_before_s and s.words_per_minute == words_per_minute and not s.resume_after


def _problem(f: Found, text: str, units: Collection[str] | None, started: set[str]) -> str:
    """Why tag ``f`` of ``text`` cannot be used ("" if it can); ``started``: names ``^start``-ed before it."""
    if f.kind in ("^^", "\\\\"):
        return ""
    if f.problem:
        return f.problem
    if f.kind in (*PIN_KINDS, "wait", "stop"):
        if not re.fullmatch(r"[A-Za-z0-9_\-./]+", f.arg):
            return f"give a unit or animation name, e.g. ^{f.kind}(point_away)"
        if units is not None and resolve_unit(f.arg, units) is None:
            return (
                f"unknown unit; known units: {', '.join(sorted(units))}; NAOqi names and your own: "
                "docs/animated-speech.md"
            )
        if f.kind in PIN_KINDS and word_index_at(text, f.start) >= len(_tokens(strip_tags(text))):
            return "it has no word after it; put it before the word it goes with"
        if f.kind in ("wait", "stop") and f.arg not in started:
            return f"no ^start({f.arg}) before it; ^run({f.arg}) plays a unit in a pause of its own"
        return ""
    if f.kind == "mode":
        return "" if f.arg in MODES else f"the mode is one of {', '.join(MODES)}"
    if f.kind in ("pau", "rspd"):
        lo, hi = (0, MAX_PAUSE_MS) if f.kind == "pau" else RSPD_PERCENT
        what = "milliseconds" if f.kind == "pau" else "percent of the rate"
        ok = f.arg.isdigit() and lo <= int(f.arg) <= hi
        return "" if ok else f"give whole {what} in [{lo}, {hi}], e.g. \\{f.kind}={(800, 120)[f.kind == 'rspd']}\\"
    if f.kind == "rst":
        return "" if not f.arg else "it takes no value: \\rst\\"
    return f"unknown tag; robogest reads {_KNOWN} (docs/animated-speech.md); write ^^ or \\\\ for the character"


def check_script(text: str, units: Collection[str] | None = None, lenient: bool = False) -> tuple[str, list[str]]:
    """``text`` with every tag checked: InputError naming the first bad one (and the fix), or with ``lenient``
    that tag removed (never spoken). Returns the text kept and the tags dropped. ``units``: the generator's unit
    names, to check names against (None: not checked here; the generator checks them)."""
    dropped: list[tuple[int, int]] = []
    started: set[str] = set()
    for f in scan(text):
        why = _problem(f, text, units, started)
        raw = text[f.start : f.end].strip()
        if why and not lenient:
            raise InputError(f"tag '{raw}': {why}; or pass --lenient (say(..., lenient=True)) to drop such tags")
        if why:
            dropped.append((f.start, f.end))
        elif f.kind == "start":
            started.add(f.arg)
    if not dropped:
        return text, []
    names = [text[a:b].strip() for a, b in dropped]
    log.warning("dropped %d tag(s) robogest cannot use (not spoken): %s", len(names), ", ".join(names))
    kept, at = [], 0
    for a, b in dropped:
        kept += [text[at:a], " "]
        at = b
    return "".join(kept) + text[at:], names


def parse_script(
    text: str, units: Mapping[str, Any] | None = None, lenient: bool = False, words_per_minute: int = 160
) -> Script:
    """Check ``text`` (:func:`check_script`) and cut it into what eSpeak speaks: a new segment at each pause
    (``\\pau``, ``^run``, ``^wait``) or rate change (``\\rspd``, ``\\rst``). ``units``: name -> unit (with
    ``stroke_s``, ``hold_s``) for the pause lengths of ``^run``/``^wait`` (the built-in units if None)."""
    from robogest.generators.lexicon import load_units

    kept, dropped = check_script(text, units, lenient)
    table = units if units is not None else load_units()
    segs: list[TextSegment] = []
    kinds: list[str] = []
    start, pause_ms, kind, resume, rate = 0, 0.0, "", None, words_per_minute
    anchors: dict[str, tuple[int, int]] = {}  # ^start-ed name -> (segment, char of the word it pins)
    for f in scan(kept):
        if f.kind == "start":
            anchors[f.arg] = (len(segs), _word_char(kept, start, f.start))
        if f.kind not in _BREAKS:
            continue
        piece = strip_tags(kept[start : f.start])
        if piece:
            segs.append(TextSegment(piece, rate, pause_ms / 1000, resume))
            kinds.append(kind)
            pause_ms, kind, resume = 0.0, "", None
        start = f.end
        unit = table.get(resolve_unit(f.arg, table) or "") if f.kind in ("run", "wait") else None
        if f.kind == "pau":
            pause_ms, kind = pause_ms + int(f.arg), kind or "rest"
        elif f.kind == "rspd":
            rate = min(450, max(80, round(words_per_minute * int(f.arg) / 100)))
        elif f.kind == "rst":
            rate = words_per_minute
        elif f.kind == "run" and unit is not None:
            pause_ms, kind = pause_ms + 1000 * (RUN_PREP_S + unit.stroke_s + unit.hold_s), "hold"
        elif f.kind == "wait" and unit is not None and f.arg in anchors:
            seg, char = anchors[f.arg]
            resume, kind = (seg, char, unit.stroke_s / 2 + unit.hold_s + WAIT_MARGIN_S), "hold"
    piece = strip_tags(kept[start:])
    if piece or pause_ms or not segs:
        segs.append(TextSegment(piece, rate, pause_ms / 1000, resume))
        kinds.append(kind)
    return Script(kept, tuple(segs), tuple(kinds), tuple(dropped))


def _word_char(text: str, seg_start: int, pos: int) -> int:
    """Character offset, in the spoken text of the segment that starts at ``seg_start``, of the first word after
    ``pos`` (the word a pin at ``pos`` goes with)."""
    before = strip_tags(text[seg_start:pos])
    return len(before) + 1 if before else 0


def synthesize_script(
    text: str,
    voice: str = "en-us",
    words_per_minute: int = 160,
    lenient: bool = False,
    units: Mapping[str, Any] | None = None,
) -> Speech:
    """Speak an annotated ``text`` with eSpeak NG; :attr:`Speech.text` keeps its tags for the generator, and its
    silent periods are those of the audio, plus each ``\\pau`` pause and ``^mode(disabled)`` stretch, minus the
    pauses in which speech waits for a gesture (``^run``, ``^wait``)."""
    from robogest import speech as sp

    script = parse_script(text, units, lenient, words_per_minute)
    if script.plain(words_per_minute):
        speech = sp.synthesize(script.segments[0].text, voice=voice, words_per_minute=words_per_minute)
        spans = _with_modes(list(speech.silent_spans), script.text, speech)
        return dataclasses.replace(speech, text=script.text, silent_spans=tuple(spans))
    speech, pauses = sp.synthesize_segments(script.segments, voice, words_per_minute, text=script.text)
    spans = list(speech.silent_spans)
    for (a, b), kind in zip(pauses, script.pause_kinds, strict=True):
        if b > a and kind == "rest":
            spans = _union(spans, [(a, b)])
        elif b > a and kind == "hold":
            spans = _minus(spans, (a, b))
    spans = _with_modes(spans, script.text, speech)
    return dataclasses.replace(speech, silent_spans=tuple(spans))


def _with_modes(spans: list[tuple[float, float]], text: str, speech: Speech) -> list[tuple[float, float]]:
    """``spans`` plus each ``^mode(disabled)`` stretch, less the time around gestures pinned inside it."""
    words = speech.words
    index = align_words(text, [w.text for w in words])
    for first, end, mode in mode_spans(text):
        ks = [k for k in index[first:end] if k is not None]
        if mode != "disabled" or not ks:
            continue
        nxt = index[end] if end < len(index) else None
        t1 = words[nxt].start_s if nxt is not None else speech.duration_s
        stretch = [(words[ks[0]].start_s, t1)]
        for tag in parse_tags(text):
            k = index[tag.word_index] if tag.word_index < len(index) else None
            if k is not None:
                stretch = _minus(stretch, (words[k].start_s - PIN_CLEAR_S[0], words[k].start_s + PIN_CLEAR_S[1]))
        spans = _union(spans, stretch)
    return spans


def _union(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for s, e in sorted([*a, *b]):
        if out and s <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], e))
        else:
            out.append((s, e))
    return out


def _minus(spans: list[tuple[float, float]], cut: tuple[float, float]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for s, e in spans:
        out += [(s, min(e, cut[0]))] if s < cut[0] else []
        out += [(max(s, cut[1]), e)] if e > cut[1] else []
    return [(s, e) for s, e in out if e - s > MIN_SPAN_S]
