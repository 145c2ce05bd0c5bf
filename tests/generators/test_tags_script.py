"""NAOqi animated-speech tags: the parser (no speech synthesis), each tag, malformed, unknown, escapes."""

from __future__ import annotations

import logging

import pytest

from robogest.errors import InputError
from robogest.generators.animated_speech import check_script, parse_script, resolve_unit
from robogest.generators.lexicon import load_units
from robogest.generators.tags import mode_spans, parse_tags, scan, strip_tags

UNITS = load_units()


def test_pins_start_run_and_gesture_to_the_next_word():
    text = "The exit is ^start(point_away) behind ^gesture(nod) the ^run(shrug) stairs."
    assert [(t.word_index, t.name, t.kind) for t in parse_tags(text)] == [
        (3, "point_away", "start"), (4, "nod", "gesture"), (5, "shrug", "run"),
    ]  # fmt: skip
    assert strip_tags(text) == "The exit is behind the stairs."


@pytest.mark.parametrize(
    "name, unit",
    [("animations/Stand/Gestures/Explain_1", "palms_up_open"), ("YouKnowWhat_3", "point_forward"),
     ("animations/Stand/Gestures/ShowSky_8", "point_away"), ("point_away", "point_away"),
     ("animations/Stand/Gestures/Hey_1", None)],
)  # fmt: skip
def test_naoqi_names_resolve_to_units(name, unit):
    assert resolve_unit(name, UNITS) == unit


def test_a_unit_named_like_the_animation_wins():
    assert resolve_unit("animations/Stand/Gestures/Explain_1", {"Explain_1", "palms_up_open"}) == "Explain_1"


def test_pause_rate_run_and_wait_cut_segments():
    s = parse_script(
        "Hello. \\pau=800\\ Nice \\rspd=150\\ to ^start(shrug) meet you ^wait(shrug) and \\rst\\ then ^run(nod) bye.",
        UNITS,
    )
    texts = [seg.text for seg in s.segments]
    assert texts == ["Hello.", "Nice", "to meet you", "and", "then", "bye."]
    assert [seg.pause_before_s for seg in s.segments][:2] == [0.0, 0.8]
    assert [seg.words_per_minute for seg in s.segments] == [160, 160, 240, 240, 160, 160]
    assert s.pause_kinds == ("", "rest", "", "hold", "", "hold")
    assert s.segments[3].resume_after is not None and s.segments[3].resume_after[:2] == (2, 3)  # "meet" in seg 2
    u = UNITS["nod"]
    assert s.segments[5].pause_before_s == pytest.approx(0.4 + u.stroke_s + u.hold_s)
    assert "^start(shrug)" in s.text and "\\pau=800\\" in s.text  # the generator reads them


def test_modes_cover_the_words_after_them():
    text = "One two ^mode(disabled) three four ^mode(random) five ^mode(contextual) six."
    assert mode_spans(text) == [(2, 4, "disabled"), (4, 5, "random")]
    assert mode_spans("Still ^mode(disabled) until the end") == [(1, 4, "disabled")]


@pytest.mark.parametrize(
    "text, words",
    [("^start(point_away", "not closed"), ("Go ^start() there", "needs a name"), ("Go ^start there", "in brackets"),
     ("Wait \\pau=800 here", "not closed"), ("Wait \\pau=abc\\ here", "whole milliseconds"),
     ("Wait \\pau=20000\\ here", r"\[0, 10000\]"), ("Fast \\rspd=400\\ now", r"\[50, 200\]"),
     ("Be ^mode(happy) now", "contextual, random, disabled"), ("Go there ^start(nod)", "no word after it"),
     ("Go ^wait(nod) there", r"no \^start\(nod\) before it"), ("Go ^start(^gesture(nod)) there", "not closed"),
     ("Go ^start(moonwalk) there", "unknown unit.*point_away")],
)  # fmt: skip
def test_malformed_tags_are_refused_naming_them(text, words):
    with pytest.raises(InputError, match=rf"tag '.*': .*{words}.*--lenient"):
        check_script(text, UNITS)


@pytest.mark.parametrize("text", ["Go ^jump(high) there", "Go \\vct=120\\ there", "Go \\rst=1\\ there"])
def test_unknown_tags_are_refused_or_dropped_with_one_warning(text, caplog):
    with pytest.raises(InputError, match=r"tag '[\^\\](jump|vct|rst)[^']*': (unknown tag|it takes no value)"):
        check_script(text, UNITS)
    with caplog.at_level(logging.WARNING, logger="robogest"):
        kept, dropped = check_script(text + " ^fly(away) now", UNITS, lenient=True)
    assert len(dropped) == 2 and len(caplog.records) == 1 and "^fly(away)" in caplog.records[0].getMessage()
    assert strip_tags(kept).split() == ["Go", "there", "now"]  # never spoken


def test_lenient_drops_malformed_tags_without_speaking_them():
    kept, dropped = check_script("The exit ^start(point_away is \\pau=x\\ here ^moonwalk", UNITS, lenient=True)
    assert strip_tags(kept) == "The exit is here" and len(dropped) == 3


def test_escapes_are_literal_characters_not_tags():
    text = "Two ^^start(three) and a \\\\pau=5\\\\ backslash"
    assert check_script(text, UNITS) == (text, [])
    assert [f.kind for f in scan(text)] == ["^^", "\\\\", "\\\\"]
    assert strip_tags(text) == "Two ^start(three) and a \\pau=5\\ backslash"
    assert parse_tags(text) == []


def test_plain_text_is_one_segment():
    s = parse_script("Just ^gesture(nod) words here.", UNITS)
    assert s.plain(160) and [seg.text for seg in s.segments] == ["Just words here."]
    assert not parse_script("\\rspd=120\\ Just words.", UNITS).plain(160)
