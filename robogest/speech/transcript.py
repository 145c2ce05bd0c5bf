"""Transcripts: reading, word normalisation, syllable counts, validation and spreading untimed text.

Accepted transcript files (chosen by suffix):

``.txt``
    Plain text without timings; words are spread over the voiced regions in proportion to their
    syllable counts (:func:`spread_words`).
``.TextGrid``
    Praat TextGrid; the interval tier named ``words`` (any case) is used, or the only interval tier
    if there is just one. Intervals labelled ``""``, ``sil``, ``<sil>``, ``sp``, ``<sp>`` or ``spn``
    are pauses, not words.
``.json``
    Word timings in any of these shapes (first match wins):

    * a list of word objects;
    * ``{"words": [...]}`` (GENEA/Trinity), also nested as ``{"segments": [{"words": [...]}]}``
      (Whisper with word timestamps); Whisper segments without words are spread over their words (below);
    * Google STT: ``{"results": [{"alternatives": [{"words": [...]}]}]}`` or a bare list of
      ``{"alternatives": [...]}`` (the first alternative is used).

    A word object names its text as ``word``, ``text``, ``token`` or ``label`` and its span as
    ``start``/``end``, ``start_time``/``end_time``, ``start_s``/``end_s``, ``startTime``/``endTime``,
    ``startOffset``/``endOffset``, ``begin``/``end`` or ``xmin``/``xmax``. Times are seconds as
    numbers, strings such as ``"1.300s"``, or ``{"seconds": 1, "nanos": 300000000}``.
``.tsv`` / ``.csv``
    One word per line: ``start<TAB>end<TAB>word`` (or comma separated), seconds; a header line is skipped.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robogest.errors import InputError
from robogest.fileio import check_input_file, read_text_capped
from robogest.speech.types import Word

#: Largest transcript file read, bytes (a 10-hour transcript with word timings is about 20 MB).
MAX_TRANSCRIPT_BYTES = 64 * 1024**2
#: Most words a transcript may give per second of its audio, on average (a BEAT2 speaker: 3.1, at most 7 in any
#: second), plus :data:`SPARE_WORDS` for short clips. More is the transcript of something else, and was slow to
#: find out: an 8 MB text for 2 s of audio ran past 120 s before failing or squeezing a million words into it.
MAX_WORDS_PER_S = 15.0
SPARE_WORDS = 20

#: TextGrid / aligner labels that mark a pause rather than a word.
PAUSE_LABELS = frozenset({"", "sil", "<sil>", "sp", "<sp>", "spn", "<eps>"})

_WORD_KEYS = ("word", "text", "token", "label")
_START_KEYS = ("start", "start_time", "start_s", "startTime", "startOffset", "begin", "xmin")
_END_KEYS = ("end", "end_time", "end_s", "endTime", "endOffset", "stop", "xmax")
_STRIP_RE = re.compile(r"[^\w']+")
_VOWEL_GROUP_RE = re.compile(r"[aeiouy]+")
#: Zero-length words (some recognisers emit them) are widened to this, s, where there is room.
_MIN_WORD_S = 0.01


@dataclass(frozen=True)
class Transcript:
    """A parsed transcript.

    Attributes
    ----------
    text : str
        The transcript's text (for timed files, the words joined by spaces).
    words : tuple of Word
        Timed words, empty when the file carries no timings.
    tokens : tuple of str
        Normalised words of an untimed transcript, to be spread by :func:`spread_words`.
    """

    text: str
    words: tuple[Word, ...] = ()
    tokens: tuple[str, ...] = ()

    @property
    def timed(self) -> bool:
        return bool(self.words)


def normalize_word(raw: str) -> str:
    """Lower case, punctuation stripped, inner apostrophes kept (``"Don't!"`` -> ``"don't"``)."""
    return _STRIP_RE.sub(" ", raw.lower().replace("\u2019", "'")).strip(" '_")


def tokenize(text: str) -> list[str]:
    """Split free text into normalised words; pure punctuation disappears."""
    out: list[str] = []
    for chunk in text.split():
        for part in normalize_word(chunk).split():
            part = part.strip("'_")
            if part:
                out.append(part)
    return out


def count_syllables(word: str) -> int:
    """Approximate English syllable count, at least 1.

    Vowel groups (``y`` counts as a vowel) with the silent-e rule: a final ``e`` is dropped unless
    the word ends in consonant + ``le`` ("table") or the ``e`` is the only vowel ("the"). Digits are
    counted one syllable each (numbers are not spelled out; good enough for a speaking rate).
    """
    w = word.lower()
    digits = sum(ch.isdigit() for ch in w)
    letters = re.sub(r"[^a-z]", "", w)
    n = len(_VOWEL_GROUP_RE.findall(letters))
    if (
        n > 1
        and letters.endswith("e")
        and not letters.endswith(("ee", "ye"))
        and not (len(letters) >= 3 and letters.endswith("le") and letters[-3] not in "aeiouy")
    ):
        n -= 1
    return max(1, n + digits)


def read_transcript(path: str | Path, audio_duration_s: float | None = None) -> Transcript:
    """Parse a transcript file; every failure is an :class:`InputError` naming the file.

    With ``audio_duration_s``, a transcript with more words than :data:`MAX_WORDS_PER_S` allows for that much
    audio is refused as soon as its words are counted, before any is timed or spread.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"transcript {p}: file not found")
    suffix = p.suffix.lower()
    if suffix == ".textgrid":  # praatio reads it (UTF-8 or UTF-16): only its size is checked here
        check_input_file(p, MAX_TRANSCRIPT_BYTES, "transcript")
        return _read_textgrid(p, audio_duration_s)
    raw = read_text_capped(p, MAX_TRANSCRIPT_BYTES, "transcript").removeprefix("\ufeff")
    if suffix == ".json":
        return _parse_json(raw, p, audio_duration_s)
    if suffix in (".tsv", ".csv"):
        _check_word_count(raw.count("\n"), audio_duration_s, p)
        return _parse_table(raw, p, delimiter="\t" if suffix == ".tsv" else ",")
    _check_word_count(len(raw.split()), audio_duration_s, p)  # C speed: before tokenizing a runaway file
    tokens = tokenize(raw)
    if not tokens:
        raise InputError(f"transcript {p}: no words in the text")
    return Transcript(text=raw.strip(), tokens=tuple(tokens))


def _check_word_count(n_words: int, audio_duration_s: float | None, p: Path) -> None:
    """Refuse more words than speech can hold in ``audio_duration_s`` (see :data:`MAX_WORDS_PER_S`)."""
    if audio_duration_s is None or n_words <= MAX_WORDS_PER_S * audio_duration_s + SPARE_WORDS:
        return
    raise InputError(
        f"transcript {p}: {n_words} words for {audio_duration_s:.2f} s of audio, more than the "
        f"{MAX_WORDS_PER_S:g} words/s (+{SPARE_WORDS}) speech can hold; is it the transcript of this audio?"
    )


def _read_textgrid(p: Path, audio_duration_s: float | None = None) -> Transcript:
    try:
        from praatio import textgrid
    except ImportError as exc:  # pragma: no cover - praatio is a core dependency
        from robogest.errors import MissingDependencyError

        raise MissingDependencyError("reading TextGrid transcripts needs praatio: pip install praatio") from exc
    try:
        tg = textgrid.openTextgrid(str(p), includeEmptyIntervals=False)
    except Exception as exc:  # praatio raises assorted exception types for malformed files
        raise InputError(f"transcript {p}: not a readable Praat TextGrid ({exc})") from exc
    interval_tiers = [name for name in tg.tierNames if getattr(tg.getTier(name), "tierType", "") == "IntervalTier"]
    chosen = next((n for n in interval_tiers if n.lower() in ("words", "word")), None)
    if chosen is None and len(interval_tiers) == 1:
        chosen = interval_tiers[0]
    if chosen is None:
        raise InputError(f"transcript {p}: no 'words' interval tier (tiers: {', '.join(tg.tierNames) or 'none'})")
    tier = tg.getTier(chosen)
    _check_word_count(len(tier.entries), audio_duration_s, p)
    entries = [(float(e.start), float(e.end), str(e.label)) for e in tier.entries]
    return _timed(entries, p)


#: ARPAbet vowel labels end in a stress digit: 1 primary, 2 secondary, 0 unstressed (CMUdict, MFA, BEAT).
_ARPABET_VOWEL_RE = re.compile(r"^[A-Z]{2}([012])$")


def read_stressed_vowels(path: str | Path) -> np.ndarray | None:
    """Onsets of the stressed vowels in a TextGrid's ``phones`` tier, seconds ``(K,)``; None when there is none.

    Forced aligners that use the CMU dictionary (Montreal Forced Aligner, the BEAT/BEAT2 TextGrids) label
    vowels in ARPAbet with a stress digit; the onsets of vowels with primary or secondary stress (``1``,
    ``2``) are where English puts its prominent syllables. Returns None (not an error) for other transcript
    formats and for TextGrids without a ``phones``/``phone`` tier or without stress-marked vowels, so a
    caller can fall back to something else.
    """
    p = Path(path)
    if p.suffix.lower() != ".textgrid":
        return None
    try:
        from praatio import textgrid

        tg = textgrid.openTextgrid(str(p), includeEmptyIntervals=False)
    except Exception as exc:  # praatio raises assorted exception types for malformed files
        raise InputError(f"transcript {p}: not a readable Praat TextGrid ({exc})") from exc
    tier = next((n for n in tg.tierNames if n.lower() in ("phones", "phone")), None)
    if tier is None:
        return None
    stressed, any_vowel = [], False
    for e in tg.getTier(tier).entries:
        m = _ARPABET_VOWEL_RE.match(str(e.label).strip().upper())
        if m:
            any_vowel = True
            if m.group(1) in "12":
                stressed.append(float(e.start))
    return np.sort(np.asarray(stressed, dtype=np.float64)) if any_vowel else None


def _timed(entries: Sequence[tuple[float, float, str]], p: Path) -> Transcript:
    """Build timed words from (start, end, label), dropping pauses and punctuation-only labels.

    A label of several words (a segment-level transcript, e.g. Whisper without word timestamps) is spread over
    its span in proportion to the words' syllable counts, as :func:`spread_words` does for untimed text.
    """
    words: list[Word] = []
    for start, end, label in entries:
        if label.strip().lower() in PAUSE_LABELS:
            continue
        tokens = tokenize(label)
        if not tokens:
            continue
        if not (math.isfinite(start) and math.isfinite(end)):
            raise InputError(f"transcript {p}: word {label!r} has a non-finite time")
        syllables = [count_syllables(tok) for tok in tokens]
        edges = start + (end - start) * np.concatenate([[0.0], np.cumsum(syllables)]) / sum(syllables)
        for tok, n, a, b in zip(tokens, syllables, edges[:-1], edges[1:], strict=True):
            words.append(Word(text=tok, start_s=float(a), end_s=float(b), syllables=n))
    if not words:
        raise InputError(f"transcript {p}: no timed words found")
    words.sort(key=lambda w: (w.start_s, w.end_s))
    return Transcript(text=" ".join(w.text for w in words), words=tuple(words))


def _parse_time(value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError("boolean is not a time")
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        return float(value.strip().rstrip("sS"))
    if isinstance(value, dict):
        return float(value.get("seconds", 0) or 0) + float(value.get("nanos", 0) or 0) * 1e-9
    raise ValueError(f"unsupported time value {value!r}")


def _first_key(d: dict[str, Any], keys: Sequence[str]) -> Any:
    for k in keys:
        if k in d and d[k] is not None:
            return d[k]
    return None


def _is_word_obj(obj: Any) -> bool:
    """A dict with a text and a span, and no ``words`` of its own (a Whisper segment with words is not a word)."""
    return (
        isinstance(obj, dict)
        and not isinstance(obj.get("words"), list)
        and _first_key(obj, _WORD_KEYS) is not None
        and _first_key(obj, _START_KEYS) is not None
        and _first_key(obj, _END_KEYS) is not None
    )


def _collect_word_objs(obj: Any) -> list[dict[str, Any]]:
    """Find word objects in the JSON shapes listed in the module docstring."""
    if isinstance(obj, list):
        if obj and all(_is_word_obj(x) for x in obj):
            return list(obj)
        found: list[dict[str, Any]] = []
        for item in obj:
            found.extend(_collect_word_objs(item))
        return found
    if isinstance(obj, dict):
        for key in ("words", "segments", "results", "result", "transcript", "transcription"):
            if isinstance(obj.get(key), (list, dict)):
                return _collect_word_objs(obj[key])
        alts = obj.get("alternatives")
        if isinstance(alts, list) and alts:
            return _collect_word_objs(alts[0])
    return []


def _parse_json(raw: str, p: Path, audio_duration_s: float | None = None) -> Transcript:
    try:
        data = json.loads(raw)
        objs = _collect_word_objs(data)
    except RecursionError:
        raise InputError(f"transcript {p}: JSON nested too deeply to be a transcript") from None
    except ValueError as exc:  # JSONDecodeError, or an integer of over 4300 digits
        raise InputError(f"transcript {p}: invalid JSON ({exc})") from None
    _check_word_count(len(objs), audio_duration_s, p)
    if not objs:
        raise InputError(
            f"transcript {p}: no word timings found (expected a list of {{word, start, end}} objects, "
            '{"words": [...]}, or Google STT results)'
        )
    entries = []
    for i, o in enumerate(objs):
        try:
            start, end = _parse_time(_first_key(o, _START_KEYS)), _parse_time(_first_key(o, _END_KEYS))
            entries.append((start, end, str(_first_key(o, _WORD_KEYS))))
        except (TypeError, ValueError) as exc:
            raise InputError(f"transcript {p}: word #{i + 1} has an unreadable time ({exc})") from exc
    return _timed(entries, p)


def _parse_table(raw: str, p: Path, delimiter: str) -> Transcript:
    entries = []
    for lineno, row in enumerate(csv.reader(raw.splitlines(), delimiter=delimiter), start=1):
        cells = [c.strip() for c in row]
        if not any(cells):
            continue
        try:
            start, end = float(cells[0]), float(cells[1])
        except (ValueError, IndexError) as exc:
            if lineno == 1:
                continue  # header
            raise InputError(f"transcript {p}: line {lineno} is not 'start{delimiter}end{delimiter}word'") from exc
        entries.append((start, end, delimiter.join(cells[2:])))
    return _timed(entries, p)


def validate_words(
    words: Sequence[Word],
    duration_s: float,
    source: str,
    tolerance_s: float = 0.05,
    skip: Callable[[str], None] | None = None,
) -> tuple[Word, ...]:
    """Check timed words against the audio; return them ready for analysis.

    Words must start at >= 0, not overlap the previous word and lie within the audio. Ends up to
    ``tolerance_s`` past the audio (rounding in aligners) are clipped; zero-length words are widened
    to 10 ms where the next word leaves room. Anything else is an :class:`InputError`, or, with ``skip``
    (datasets, where one bad word must not lose a recording), a message to ``skip`` and the word dropped.
    """
    out: list[Word] = []
    ws = sorted(words, key=lambda w: (w.start_s, w.end_s))

    def bad(message: str) -> None:
        if skip is None:
            raise InputError(message)
        skip(message)

    for i, w in enumerate(ws):
        where = f"{source}: word #{i + 1} {w.text!r} ({w.start_s:.3f}-{w.end_s:.3f} s)"
        if w.start_s < 0.0:
            bad(f"{where} starts before 0 s; transcript cannot be aligned")
            continue
        if w.end_s < w.start_s:
            bad(f"{where} ends before it starts; transcript cannot be aligned")
            continue
        if w.start_s >= duration_s or w.end_s > duration_s + tolerance_s:
            bad(f"{where} lies beyond the audio's end ({duration_s:.3f} s); wrong transcript?")
            continue
        if out and w.start_s < out[-1].end_s - 1e-6:
            bad(f"{where} overlaps the previous word {out[-1].text!r}; transcript cannot be aligned")
            continue
        start = max(w.start_s, out[-1].end_s) if out else w.start_s
        end = min(w.end_s, duration_s)
        if end - start < _MIN_WORD_S:
            limit = ws[i + 1].start_s if i + 1 < len(ws) else duration_s
            end = min(start + _MIN_WORD_S, limit, duration_s)
            if end <= start:
                bad(f"{where} has no duration and no room to widen it")
                continue
        out.append(Word(text=w.text, start_s=float(start), end_s=float(end), syllables=max(1, int(w.syllables))))
    return tuple(out)


def spread_words(tokens: Sequence[str], regions: Sequence[tuple[float, float]], source: str) -> tuple[Word, ...]:
    """Spread untimed words over voiced regions in proportion to their syllable counts.

    The regions are laid end to end into one "speech clock"; each word takes a share of it equal to its
    share of the syllables. A word that would straddle two regions is clipped to the region holding
    most of it, so no word spans a pause.

    Parameters
    ----------
    tokens : sequence of str
        Normalised words in spoken order.
    regions : sequence of (float, float)
        Voiced ``(start_s, end_s)`` spans, increasing, non-overlapping.
    source : str
        Name used in error messages.
    """
    regions = [(float(a), float(b)) for a, b in regions if b > a]
    if not tokens:
        return ()
    if not regions:
        raise InputError(f"{source}: the audio has no voiced region to spread the transcript's words over")
    syl = [count_syllables(t) for t in tokens]
    total_syl = float(sum(syl))
    lengths = [b - a for a, b in regions]
    offsets = [0.0]
    for length in lengths:
        offsets.append(offsets[-1] + length)
    total = offsets[-1]

    def to_time(x: float) -> tuple[float, int]:
        """Speech-clock position -> (time, region index)."""
        x = min(max(x, 0.0), total)
        k = 0
        while k + 1 < len(regions) and x > offsets[k + 1]:
            k += 1
        return regions[k][0] + (x - offsets[k]), k

    words: list[Word] = []
    cum = 0.0
    for token, s in zip(tokens, syl, strict=True):
        x0, x1 = total * cum / total_syl, total * (cum + s) / total_syl
        cum += s
        (t0, k0), (t1, k1) = to_time(x0), to_time(x1)
        if x0 >= offsets[k0 + 1] - 1e-12 and k0 + 1 < len(regions):
            t0, k0 = regions[k0 + 1][0], k0 + 1  # starts exactly at a region end -> next region
        if k1 != k0:  # straddles a pause: keep the larger part
            if regions[k0][1] - t0 >= t1 - regions[k1][0]:
                t1 = regions[k0][1]
            else:
                t0 = regions[k1][0]
        if words and t0 < words[-1].end_s:
            t0 = words[-1].end_s
        if t1 <= t0:
            continue  # a sliver squeezed out by a neighbour; rare, and only for very short regions
        words.append(Word(text=token, start_s=t0, end_s=t1, syllables=s))
    return tuple(words)
