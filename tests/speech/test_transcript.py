"""Transcript parsing, syllable counts, validation and spreading of untimed text."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robogest.errors import InputError
from robogest.speech.transcript import (
    count_syllables,
    read_stressed_vowels,
    read_transcript,
    spread_words,
    tokenize,
    validate_words,
)
from robogest.speech.types import Word


@pytest.mark.parametrize(
    ("word", "n"),
    [
        ("the", 1),
        ("cat", 1),
        ("make", 1),
        ("table", 2),
        ("little", 2),
        ("hello", 2),
        ("beautiful", 3),
        ("robot", 2),
        ("gesture", 2),
        ("free", 1),
        ("rhythm", 1),
        ("syllable", 3),
        ("um", 1),
        ("42", 2),
    ],
)
def test_count_syllables(word: str, n: int):
    assert count_syllables(word) == n


def test_tokenize_strips_punctuation_keeps_apostrophes():
    assert tokenize("Don't stop -- it's fine, OK?! …") == ["don't", "stop", "it's", "fine", "ok"]


def write_textgrid(path: Path, intervals: list[tuple[float, float, str]], xmax: float, tier: str = "words") -> Path:
    lines = [
        'File type = "ooTextFile"',
        'Object class = "TextGrid"',
        "",
        "xmin = 0",
        f"xmax = {xmax}",
        "tiers? <exists>",
        "size = 1",
        "item []:",
        "    item [1]:",
        '        class = "IntervalTier"',
        f'        name = "{tier}"',
        "        xmin = 0",
        f"        xmax = {xmax}",
        f"        intervals: size = {len(intervals)}",
    ]
    for i, (a, b, text) in enumerate(intervals, start=1):
        lines += [
            f"        intervals [{i}]:",
            f"            xmin = {a}",
            f"            xmax = {b}",
            f'            text = "{text}"',
        ]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_textgrid_words_tier_skips_pauses(tmp_path: Path):
    p = write_textgrid(
        tmp_path / "a.TextGrid",
        [(0, 0.5, ""), (0.5, 0.9, "Hello"), (0.9, 1.0, "sil"), (1.0, 1.4, "world"), (1.4, 1.6, "<sil>"), (1.6, 2, "")],
        2.0,
    )
    tr = read_transcript(p)
    assert tr.timed
    assert [(w.text, w.start_s, w.end_s) for w in tr.words] == [("hello", 0.5, 0.9), ("world", 1.0, 1.4)]
    assert tr.words[0].syllables == 2
    assert tr.text == "hello world"


def test_textgrid_single_tier_with_other_name_is_used(tmp_path: Path):
    p = write_textgrid(tmp_path / "b.TextGrid", [(0, 0.5, "hi")], 1.0, tier="transcript")
    assert [w.text for w in read_transcript(p).words] == ["hi"]


def test_json_variants(tmp_path: Path):
    plain = [{"word": "Hi,", "start": 0.1, "end": 0.3}, {"text": "there", "start_time": 0.3, "end_time": 0.6}]
    genea = {"words": [{"word": "hi", "start_s": 0.1, "end_s": 0.3}]}
    google = [
        {
            "alternatives": [
                {"transcript": "hi there", "words": [{"word": "hi", "start_time": "0.100s", "end_time": "0.300s"}]},
                {"transcript": "high", "words": [{"word": "high", "start_time": "0.1s", "end_time": "0.3s"}]},
            ]
        },
        {"alternatives": [{"words": [{"word": "there", "startTime": {"seconds": 1, "nanos": 5e8}, "endTime": "2s"}]}]},
    ]
    results = {"results": google}
    for name, data, expect in [
        ("plain", plain, [("hi", 0.1, 0.3), ("there", 0.3, 0.6)]),
        ("genea", genea, [("hi", 0.1, 0.3)]),
        ("google", google, [("hi", 0.1, 0.3), ("there", 1.5, 2.0)]),
        ("results", results, [("hi", 0.1, 0.3), ("there", 1.5, 2.0)]),
    ]:
        p = tmp_path / f"{name}.json"
        p.write_text(json.dumps(data))
        got = [(w.text, w.start_s, w.end_s) for w in read_transcript(p).words]
        assert got == [(t, pytest.approx(a), pytest.approx(b)) for t, a, b in expect], name


def test_tsv_with_header(tmp_path: Path):
    p = tmp_path / "w.tsv"
    p.write_text("start\tend\tword\n0.0\t0.4\tHello\n0.5\t0.9\tyou\n")
    assert [w.text for w in read_transcript(p).words] == ["hello", "you"]


def test_plain_text_is_untimed(tmp_path: Path):
    p = tmp_path / "t.txt"
    p.write_text("Hello there, robot!\n")
    tr = read_transcript(p)
    assert not tr.timed
    assert tr.tokens == ("hello", "there", "robot")
    assert tr.text == "Hello there, robot!"


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("bad.json", "{not json", "invalid JSON"),
        ("nowords.json", '{"foo": 1}', "no word timings"),
        ("badtime.json", '[{"word": "a", "start": "soon", "end": 1}]', "unreadable time"),
        ("empty.txt", " ... \n", "no words"),
        ("bad.TextGrid", "this is not a textgrid", "not a readable Praat TextGrid"),
        ("bad.tsv", "0.1\t0.2\tok\nx\ty\tz\n", "line 2"),
    ],
)
def test_bad_transcripts_raise_input_error(tmp_path: Path, name: str, content: str, match: str):
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(InputError, match=match):
        read_transcript(p)


def test_missing_transcript(tmp_path: Path):
    with pytest.raises(InputError, match="file not found"):
        read_transcript(tmp_path / "nope.txt")


def test_validate_words_errors_and_fixes():
    ok = validate_words([Word("b", 0.5, 0.8), Word("a", 0.1, 0.4)], 1.0, "x")
    assert [w.text for w in ok] == ["a", "b"]
    clipped = validate_words([Word("a", 0.5, 1.03)], 1.0, "x")
    assert clipped[0].end_s == 1.0
    widened = validate_words([Word("a", 0.5, 0.5)], 1.0, "x")
    assert widened[0].end_s == pytest.approx(0.51)
    with pytest.raises(InputError, match="beyond the audio's end"):
        validate_words([Word("a", 0.5, 1.5)], 1.0, "x")
    with pytest.raises(InputError, match="beyond the audio's end"):
        validate_words([Word("a", 1.2, 1.3)], 1.0, "x")
    with pytest.raises(InputError, match="overlaps"):
        validate_words([Word("a", 0.1, 0.5), Word("b", 0.3, 0.6)], 1.0, "x")
    with pytest.raises(InputError, match="before 0 s"):
        validate_words([Word("a", -0.1, 0.5)], 1.0, "x")
    with pytest.raises(InputError, match="ends before it starts"):
        validate_words([Word("a", 0.5, 0.4)], 1.0, "x")


def test_spread_words_by_syllables_within_regions():
    # hello (2) world (1) beautiful (3) = 6 syllables over 3 s of speech in two regions.
    words = spread_words(["hello", "world", "beautiful"], [(1.0, 2.5), (3.0, 4.5)], "x")
    assert [(w.text, round(w.start_s, 6), round(w.end_s, 6)) for w in words] == [
        ("hello", 1.0, 2.0),
        ("world", 2.0, 2.5),
        ("beautiful", 3.0, 4.5),
    ]


def test_spread_word_straddling_a_pause_keeps_larger_part():
    words = spread_words(["a", "b"], [(0.0, 1.2), (2.0, 2.8)], "x")  # b would run 1.0..1.2 + 2.0..2.8
    assert (words[1].start_s, words[1].end_s) == pytest.approx((2.0, 2.8))
    assert words[0].end_s <= words[1].start_s


def test_spread_without_regions_is_input_error():
    with pytest.raises(InputError, match="no voiced region"):
        spread_words(["hello"], [], "clip.wav")


def test_whisper_word_level_json_gives_its_words_not_its_segments(tmp_path: Path):
    """Whisper with word timestamps: 2 segments carrying 8 words are 8 words."""

    def seg(s, e, ws):
        return {
            "start": s,
            "end": e,
            "text": " ".join(w for w, _, _ in ws),
            "words": [{"word": f" {w}", "start": a, "end": b, "probability": 0.9} for w, a, b in ws],
        }

    data = {"text": "...", "segments": [
        seg(0.0, 1.6, [("Hello", 0.0, 0.4), ("there,", 0.4, 0.8), ("my", 0.9, 1.1), ("friend.", 1.1, 1.6)]),
        seg(2.0, 3.6, [("How", 2.0, 2.3), ("are", 2.3, 2.6), ("you", 2.6, 3.0), ("today?", 3.0, 3.6)]),
    ], "language": "en"}  # fmt: skip
    p = tmp_path / "w.json"
    p.write_text(json.dumps(data))
    tr = read_transcript(p)
    assert [w.text for w in tr.words] == ["hello", "there", "my", "friend", "how", "are", "you", "today"]
    assert (tr.words[1].start_s, tr.words[1].end_s) == (0.4, 0.8)


def test_segment_level_json_is_spread_over_its_words_by_syllables(tmp_path: Path):
    p = tmp_path / "s.json"
    p.write_text(json.dumps({"segments": [{"id": 0, "start": 1.0, "end": 2.0, "text": " Hello robot"}]}))
    words = read_transcript(p).words
    assert [w.text for w in words] == ["hello", "robot"]
    assert words[0].start_s == 1.0 and words[-1].end_s == pytest.approx(2.0)
    assert words[0].end_s == pytest.approx(words[1].start_s) == pytest.approx(1.5)  # 2 + 2 syllables


def test_validate_words_can_skip_bad_words_instead_of_raising():
    ws = [Word("a", 0.0, 0.5, 1), Word("b", 0.5, 0.5, 1), Word("c", 0.5, 0.9, 1), Word("d", 3.0, 3.2, 1)]
    with pytest.raises(InputError, match=r"'b'.*no duration"):
        validate_words(ws, 2.0, "t")
    skipped: list[str] = []
    out = validate_words(ws, 2.0, "t", skip=skipped.append)
    assert [w.text for w in out] == ["a", "c"] and len(skipped) == 2
    assert "'b'" in skipped[0] and "beyond the audio" in skipped[1]


def test_read_stressed_vowels_from_phones_tier(tmp_path: Path):
    phones = [(0.0, 0.1, "HH"), (0.1, 0.3, "AY1"), (0.3, 0.4, "T"), (0.4, 0.5, "IH0"), (0.5, 0.7, "EH2")]
    p = write_textgrid(tmp_path / "p.TextGrid", phones, 0.7, tier="phones")
    assert read_stressed_vowels(p) == pytest.approx([0.1, 0.5])  # primary and secondary stress, not IH0


def test_read_stressed_vowels_is_none_without_stress_marked_phones(tmp_path: Path):
    words = write_textgrid(tmp_path / "w.TextGrid", [(0.0, 0.5, "hi")], 1.0)
    ipa = write_textgrid(tmp_path / "i.TextGrid", [(0.0, 0.2, "h"), (0.2, 0.5, "aɪ")], 1.0, tier="phones")
    txt = tmp_path / "t.txt"
    txt.write_text("hi")
    assert read_stressed_vowels(words) is None and read_stressed_vowels(ipa) is None
    assert read_stressed_vowels(txt) is None
