"""NAOqi animated-speech tags end to end through `robogest speak` and the Python pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.errors import InputError
from robogest.pipeline import load_speech_input
from robogest.speech import tts
from robogest.trajectory import Trajectory


def _speak(tmp_path, name: str, *args: str) -> Trajectory:
    out = tmp_path / f"{name}.npz"
    assert main(["speak", *args, "--save", str(out)]) == 0
    return Trajectory.load(out)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2], strict=True))


def _spoken(monkeypatch) -> list[str]:
    """Every text handed to eSpeak NG."""
    said: list[str] = []
    real = tts._run_worker

    def spy(text, *a, **k):
        said.append(text)
        return real(text, *a, **k)

    monkeypatch.setattr(tts, "_run_worker", spy)
    return said


@pytest.mark.slow
def test_tagged_text_speaks_no_tag_and_moves(tmp_path, monkeypatch):
    said = _spoken(monkeypatch)
    traj = _speak(tmp_path, "a", "The exit is ^start(point_away) behind the stairs.")
    assert said == ["The exit is behind the stairs."]
    np.testing.assert_allclose(traj.q_rad[-1], traj.rest_q_rad, atol=1e-9)


def test_unknown_tag_exit_2_one_line(tmp_path, capsys, monkeypatch):
    said = _spoken(monkeypatch)
    assert main(["speak", "The exit is ^jump(point_away) behind the stairs.", "--save", str(tmp_path / "b.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "^jump(point_away)" in err and "--lenient" in err
    assert said == [] and not (tmp_path / "b.npz").exists()


@pytest.mark.slow
def test_lenient_drops_with_one_warning_and_never_speaks_it(tmp_path, capsys, monkeypatch):
    said = _spoken(monkeypatch)
    _speak(tmp_path, "c", "The exit is ^jump(point_away) behind \\vct=120\\ the stairs.", "--lenient")
    err = [ln for ln in capsys.readouterr().err.splitlines() if "WARNING" in ln or "warning" in ln]
    assert len(err) == 1 and "^jump(point_away)" in err[0] and "\\vct=120\\" in err[0]
    assert said == ["The exit is behind the stairs."]


@pytest.mark.slow
def test_pause_tag_is_a_silent_period_the_robot_rests_in(tmp_path, monkeypatch):
    said = _spoken(monkeypatch)
    text = "Hello there, my friend. \\pau={}\\ Nice to meet you all today."
    speech = load_speech_input(text=text.format(800))
    assert said == ["Hello there, my friend.", "Nice to meet you all today."]
    (a, b), *_ = [s for s in speech.silent_spans if s[0] > 0.5]
    assert b - a == pytest.approx(0.8, abs=0.05)
    for ms, at_rest_s in ((800, 0.0), (1600, 1.0)):
        traj = _speak(tmp_path, f"p{ms}", text.format(ms))
        ((i, j),) = [(i, j) for i, j in _runs(traj.silent) if i > 0]
        assert (j - i) / traj.fps == pytest.approx(ms / 1000, abs=0.05)  # the saved trajectory's silent window
        off_rest = np.abs(traj.q_rad[i:j] - traj.rest_q_rad).max(axis=1)
        assert (off_rest < 1e-9).sum() / traj.fps >= at_rest_s  # minus the retraction and the lead back out


@pytest.mark.slow
def test_mode_disabled_rests_over_its_span(tmp_path):
    text = ("Let me show you this. ^mode(disabled) Now I stand completely still while I say a long sentence "
            "with many big words in it. ^mode(contextual) And now everything moves again, all of it!")  # fmt: skip
    speech = load_speech_input(text=text)
    now = next(w for w in speech.words if w.text == "now")
    it = speech.words[[w.text for w in speech.words].index("and") - 1]  # "...words in it."
    assert any(a <= now.start_s + 0.01 and b >= it.end_s for a, b in speech.silent_spans)
    traj = _speak(tmp_path, "d", text)
    t = traj.t_s
    inside = (t >= now.start_s + 0.6) & (t <= it.end_s - 0.4)  # after the retraction, before leaving rest
    np.testing.assert_allclose(traj.q_rad[inside], np.broadcast_to(traj.rest_q_rad, traj.q_rad[inside].shape),
                               atol=1e-6)  # fmt: skip
    plain = _speak(tmp_path, "e", text.replace("^mode(disabled) ", "").replace("^mode(contextual) ", ""))
    inside = (plain.t_s >= now.start_s + 0.6) & (plain.t_s <= it.end_s - 0.4)
    assert np.abs(plain.q_rad[inside] - plain.rest_q_rad).max() > 0.05  # it gestures there otherwise


def _tag_strokes(text: str) -> tuple[object, list[tuple[float, float, str]]]:
    from robogest.generators.rhythm import RhythmGenerator

    speech = load_speech_input(text=text)
    g = RhythmGenerator()
    return speech, [(a, b, e.unit) for a, b, e in g.strokes(speech) if e.source.startswith("tag:")]


def test_run_plays_its_unit_in_a_pause_speech_waits_for():
    speech, strokes = _tag_strokes("Look ^run(point_away) there is the door.")
    look, there = speech.words[0], speech.words[1]
    assert there.start_s - look.end_s >= 0.9  # speech waits (prep + stroke + hold of point_away)
    ((a, b, unit),) = strokes
    assert unit == "point_away" and look.end_s <= a < b <= there.start_s
    assert not any(s < there.start_s and e > look.end_s for s, e in speech.silent_spans)  # held, not a rest


def test_wait_pauses_until_the_started_unit_ends():
    speech, _ = _tag_strokes("It is ^start(spread_both) big ^wait(spread_both) and then some more words.")
    big, and_ = speech.words[2], speech.words[3]
    assert and_.start_s - big.start_s >= 0.3 + 0.15 + 0.3  # margin + half the stroke + the hold
    no_wait = load_speech_input(text="It is ^start(spread_both) big and then some more words.")
    assert no_wait.words[3].start_s < and_.start_s - 0.2


def test_a_pinned_unit_plays_inside_a_disabled_stretch():
    text = "Now ^mode(disabled) I stand still while I say a long sentence and ^start(point_away) there it is I said."
    speech, strokes = _tag_strokes(text)
    there = next(w for w in speech.words if w.text == "there")
    assert [u for *_, u in strokes] == ["point_away"]
    assert any(b <= there.start_s - 0.5 for _, b in speech.silent_spans)  # rest before it
    assert not any(a <= there.start_s <= b for a, b in speech.silent_spans)


def test_rate_tag_speaks_faster():
    fast = load_speech_input(text="\\rspd=200\\ One two three four five six seven eight.")
    slow = load_speech_input(text="One two three four five six seven eight.")
    assert fast.words[-1].end_s < 0.7 * slow.words[-1].end_s


@pytest.mark.slow
def test_robot_say_refuses_or_drops_unknown_tags_and_never_speaks_them(monkeypatch, caplog):
    import logging

    from robogest.live import Robot

    said = _spoken(monkeypatch)
    # prepared in this process so that the spy sees what eSpeak is given (the child process prepares the same:
    # tests/live/test_prepare.py)
    with Robot("humanoid_xl430", backend="sim", idle=False, time_scale=4.0, warm_up=False, prepare="thread") as robot:
        with pytest.raises(InputError, match=r"tag '\^jump\(away\)': unknown tag"):
            robot.say("The exit is ^jump(away) behind the stairs.")
        assert said == []
        with caplog.at_level(logging.WARNING, logger="robogest"):
            h = robot.say("The exit is ^jump(away) behind ^start(point_away) the stairs.", lenient=True)
    assert said == ["The exit is behind the stairs."] and h.trajectory is not None
    assert [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()] == [
        "dropped 1 tag(s) robogest cannot use (not spoken): ^jump(away)"
    ]


@pytest.mark.slow
def test_serve_say_takes_lenient():
    import json

    from tests.live.test_serve import _client, _recv, _start

    proc, url = _start("--time-scale", "4")
    try:
        with _client(url) as ws:
            _recv(ws, "hello")
            ws.send(json.dumps({"type": "say", "text": "Go ^jump(away) now."}))
            assert "tag '^jump(away)': unknown tag" in _recv(ws, "error")["message"]
            ws.send(json.dumps({"type": "say", "text": "Go ^jump(away) now.", "lenient": "yes"}))
            assert '"lenient" must be true or false' in _recv(ws, "error")["message"]
            ws.send(json.dumps({"type": "say", "text": "Go ^jump(away) now.", "lenient": True}))
            _recv(ws, "accepted")
    finally:
        proc.terminate()
        proc.wait(60)


def test_a_gesture_file_unit_takes_a_naoqi_name(tmp_path):
    from robogest.generators import lexicon as lx
    from robogest.generators.rhythm import RhythmGenerator

    (tmp_path / "naoqi.yaml").write_text(
        "units:\n  Hey:\n    hand: right\n    size: large\n    kind: semantic\n"
        "    prep: {r_flex: 0.9, r_elbow: 0.6}\n    stroke: {r_flex: 1.3, r_elbow: 0.9, r_abd: 0.3}\n"
    )
    rep = lx.Repertoire(lx.load_units([tmp_path, *lx.search_path()]))
    text = "Hello! ^start(animations/Stand/Gestures/Hey_1) Nice to meet you."
    speech = load_speech_input(text=text, units=rep.units)
    plan = RhythmGenerator(repertoire=rep).plan(speech)
    assert [(e.unit, e.source) for e in plan if e.source.startswith("tag:")] == [("Hey", "tag:nice")]
    with pytest.raises(InputError, match=r"\^start\(animations/Stand/Gestures/Hey_1\): unknown unit"):
        RhythmGenerator().plan(load_speech_input(text=text))  # the built-in units have no wave
