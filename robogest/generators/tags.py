"""Inline tags in text, and lining the text's sentences up with the spoken words.

Gesture pins: ``^gesture(NAME)`` anywhere in the text pins unit NAME to the next word, e.g.
``Look ^gesture(point_away) over there``: the stroke of ``point_away`` lands on "over". NAOqi's
``^start(NAME)`` pins the same way, ``^run(NAME)`` plays NAME in a pause before the next word, and
``^mode(contextual|random|disabled)`` sets the body language of the words after it (see
:mod:`robogest.generators.animated_speech` and docs/animated-speech.md, which also cover ``^wait``, ``^stop`` and
the TTS's ``\\pau=MS\\``, ``\\rspd=N\\``, ``\\rst\\``). ``^^`` and ``\\\\`` are a literal ``^`` and ``\\``.

Tags are removed before the text is spoken; :attr:`Speech.text` keeps them, and the generator reads them from there.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from robogest.errors import InputError

#: A ``^gesture(NAME)`` tag (the original syntax).
TAG = re.compile(r"\^gesture\(\s*([^)]*?)\s*\)")
#: Anything that looks like a tag (well-formed or not), or an escape: ``^^``, ``\\``, ``^name(arg)``, ``^name``,
#: ``^name(arg`` (unclosed), ``\name=value\``, ``\name\``, ``\name=value`` (unclosed); the name is group ``caret``
#: or ``slash``.
ANY_TAG = re.compile(
    r"\^\^|\\\\"
    r"|\^(?P<caret>[A-Za-z_]\w*)(?:\(\s*[^()\s]*\s*\)?)?"
    r"|\\(?P<slash>[A-Za-z_]\w*)(?:=[^\\\s]*)?\\?"
)
_CARET = re.compile(r"\^([A-Za-z_]\w*)\(\s*([^()\s]*)\s*\)")
_BACKSLASH = re.compile(r"\\([A-Za-z_]\w*)(?:=([^\\\s]*))?\\")
_TOKEN = re.compile(r"[A-Za-z0-9\u00C0-\u024F']+")
_SENTENCE_END = re.compile(r"[.!?]+|\.\.\.|…")
#: Tags that pin a unit to the next word.
PIN_KINDS = ("gesture", "start", "run")
#: ``^mode`` values (NAOqi's body language modes).
MODES = ("contextual", "random", "disabled")


@dataclass(frozen=True)
class Tag:
    """``name`` pinned to the ``word_index``-th word of the text (0-based, counting spoken words); ``kind`` is the
    tag (``gesture``, ``start``: the stroke on that word; ``run``: in the pause before it)."""

    word_index: int
    name: str
    kind: str = "gesture"


@dataclass(frozen=True)
class Found:
    """One tag-like match of ``text[start:end]``: ``kind`` (``^`` tags: gesture, start...; ``\\`` tags: pau, rspd...;
    ``"^^"`` / ``"\\\\"`` for an escape), ``arg`` (the name or value, "" if none) and ``problem`` ("" if
    well-formed)."""

    start: int
    end: int
    kind: str
    arg: str
    problem: str = ""


def scan(text: str) -> list[Found]:
    """Every tag-like piece of ``text`` in order, checked for form only (not whether the tag is known)."""
    out: list[Found] = []
    for m in ANY_TAG.finditer(text):
        s = m.group(0)
        if s in ("^^", "\\\\"):
            out.append(Found(m.start(), m.end(), s, ""))
        elif s.startswith("^"):
            full = _CARET.fullmatch(s)
            kind = m.group("caret").lower()
            if full:
                prob = "" if full.group(2) else "it needs a name between the brackets, e.g. ^start(point_away)"
                out.append(Found(m.start(), m.end(), kind, full.group(2), prob))
            else:
                how = "is not closed with ')'" if "(" in s else "needs a name in brackets, e.g. ^start(point_away)"
                out.append(Found(m.start(), m.end(), kind, "", f"it {how}"))
        else:
            full = _BACKSLASH.fullmatch(s)
            kind = m.group("slash").lower()
            if full:
                out.append(Found(m.start(), m.end(), kind, full.group(2) or ""))
            else:
                out.append(Found(m.start(), m.end(), kind, "", "it is not closed with '\\', e.g. \\pau=800\\"))
    return out


def _clean(text: str) -> str:
    """Tags replaced by a space, escapes by their character (not tidied: word counting only)."""
    return ANY_TAG.sub(lambda m: {"^^": "^", "\\\\": "\\"}.get(m.group(0), " "), text)


def _tokens(text: str) -> list[str]:
    return [t.lower().strip("'") for t in _TOKEN.findall(text) if t.strip("'")]


def strip_tags(text: str) -> str:
    """The text to speak: tags (and anything that looks like one) removed, escapes resolved, spaces tidied."""
    return re.sub(r"\s{2,}", " ", _clean(text)).strip()


def word_index_at(text: str, pos: int) -> int:
    """How many spoken words of ``text`` come before character ``pos``."""
    return len(_tokens(_clean(text[:pos])))


def parse_tags(text: str) -> list[Tag]:
    """The gesture pins (``^gesture``, ``^start``, ``^run``) of ``text`` with the index of the word each one pins;
    InputError for an empty or dangling one."""
    out: list[Tag] = []
    n_words = len(_tokens(_clean(text)))
    for f in scan(text):
        if f.kind not in PIN_KINDS:
            continue
        raw = text[f.start : f.end]
        if f.problem or not re.fullmatch(r"[A-Za-z0-9_\-./]+", f.arg):
            raise InputError(f"gesture tag {raw!r}: give a unit name, e.g. ^{f.kind}(point_away)")
        idx = word_index_at(text, f.start)
        if idx >= n_words:
            raise InputError(f"gesture tag {raw!r} has no word after it; put it before the word it goes with")
        out.append(Tag(idx, f.arg, f.kind))
    return out


def mode_spans(text: str) -> list[tuple[int, int, str]]:
    """``(first_word, end_word, mode)`` for each stretch after a ``^mode`` tag that is not ``contextual`` (the
    default): words ``first_word <= k < end_word`` of the spoken text. Unknown modes are left out (the script
    parser refuses them)."""
    out: list[tuple[int, int, str]] = []
    mode, first = "contextual", 0
    for f in scan(text):
        if f.kind != "mode" or f.problem or f.arg not in MODES:
            continue
        k = word_index_at(text, f.start)
        if mode != "contextual" and k > first:
            out.append((first, k, mode))
        mode, first = f.arg, k
    n = len(_tokens(_clean(text)))
    if mode != "contextual" and n > first:
        out.append((first, n, mode))
    return out


def sentences(text: str) -> list[tuple[int, int, str]]:
    """Sentences as ``(first_word, last_word, end)`` word indices of the spoken text; ``end`` is the closing
    punctuation (``"?"``, ``"!"``, ``"."`` or ``""``)."""
    clean = _clean(text)
    out: list[tuple[int, int, str]] = []
    first = 0
    for m in _SENTENCE_END.finditer(clean):
        n = len(_tokens(clean[: m.end()]))
        if n > first:
            out.append((first, n - 1, "?" if "?" in m.group(0) else m.group(0)[0]))
            first = n
    n = len(_tokens(clean))
    if n > first:
        out.append((first, n - 1, ""))
    return out


def align_words(text: str, spoken: list[str]) -> list[int | None]:
    """For each word of ``text``, the index of the same word among ``spoken`` (None if eSpeak said it otherwise).

    Greedy, in order, looking a few words ahead, so a number spoken as two words or a dropped token only
    shifts the match locally.
    """
    toks = _tokens(_clean(text))
    norm = [re.sub(r"[^a-z0-9\u00e0-\u024f']", "", s.lower()) for s in spoken]
    out: list[int | None] = []
    j = 0
    for t in toks:
        hit = next((k for k in range(j, min(j + 4, len(norm))) if norm[k] == t), None)
        if hit is None:
            out.append(j if j < len(norm) and len(toks) == len(norm) else None)
            j += 1 if len(toks) == len(norm) else 0
            continue
        out.append(hit)
        j = hit + 1
    return out
