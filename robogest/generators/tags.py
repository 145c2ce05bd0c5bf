"""Inline gesture tags in text, and lining the text's sentences up with the spoken words.

Syntax: ``^gesture(NAME)`` anywhere in the text pins unit NAME to the next word, e.g.
``Look ^gesture(point_away) over there``: the stroke of ``point_away`` lands on "over". Tags are removed
before the text is spoken; :attr:`Speech.text` keeps them, and the generator reads them from there.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from robogest.errors import InputError

TAG = re.compile(r"\^gesture\(\s*([^)]*?)\s*\)")
_TOKEN = re.compile(r"[A-Za-z0-9\u00C0-\u024F']+")
_SENTENCE_END = re.compile(r"[.!?]+|\.\.\.|…")


@dataclass(frozen=True)
class Tag:
    """``name`` pinned to the ``word_index``-th word of the text (0-based, counting spoken words)."""

    word_index: int
    name: str


def _tokens(text: str) -> list[str]:
    return [t.lower().strip("'") for t in _TOKEN.findall(text) if t.strip("'")]


def strip_tags(text: str) -> str:
    """The text to speak: tags removed, spaces tidied."""
    return re.sub(r"\s{2,}", " ", TAG.sub(" ", text)).strip()


def parse_tags(text: str) -> list[Tag]:
    """The tags of ``text`` with the index of the word each one pins; InputError for an empty or dangling tag."""
    out: list[Tag] = []
    n_words = len(_tokens(TAG.sub(" ", text)))
    for m in TAG.finditer(text):
        name = m.group(1)
        if not re.fullmatch(r"[A-Za-z0-9_\-]+", name):
            raise InputError(f"gesture tag {m.group(0)!r}: give a unit name, e.g. ^gesture(point_away)")
        idx = len(_tokens(TAG.sub(" ", text[: m.start()])))
        if idx >= n_words:
            raise InputError(f"gesture tag {m.group(0)!r} has no word after it; put it before the word it goes with")
        out.append(Tag(idx, name))
    return out


def sentences(text: str) -> list[tuple[int, int, str]]:
    """Sentences as ``(first_word, last_word, end)`` word indices of the spoken text; ``end`` is the closing
    punctuation (``"?"``, ``"!"``, ``"."`` or ``""``)."""
    clean = TAG.sub(" ", text)
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
    toks = _tokens(TAG.sub(" ", text))
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
