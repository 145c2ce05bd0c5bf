"""End-to-end through `robogest speak`: inline gesture tags, user gesture files, --amount / --style / --gestures."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.generators.rhythm import RhythmGenerator
from robogest.pipeline import load_speech_input
from robogest.trajectory import Trajectory

TAGGED = "The exit is ^gesture(point_away) behind the stairs, on the left."


def _speak(tmp_path, name: str, *args: str) -> Trajectory:
    out = tmp_path / f"{name}.npz"
    assert main(["speak", *args, "--save", str(out)]) == 0
    return Trajectory.load(out)


def _speech_speed(traj: Trajectory) -> float:
    """Mean joint speed (rad/s) over the frames that are not silent."""
    v = np.abs(np.diff(traj.q_rad, axis=0)).sum(axis=1) * traj.fps
    return float(v[~traj.silent[1:]].mean())


def test_tag_pins_its_unit_to_the_next_word_within_20_ms(tmp_path):
    speech = load_speech_input(text=TAGGED)
    assert "^gesture" in speech.text and all("gesture" not in w.text for w in speech.words)  # not spoken
    g = RhythmGenerator(fps=200.0, sway_rad=0.0, drift_m_s=0.0)
    (tag,) = [e for e in g.plan(speech, seed=0) if e.source.startswith("tag:")]
    word = next(w for w in speech.words if w.text == "behind")
    assert tag.unit == "point_away" and tag.source == "tag:behind"
    assert word.start_s - 0.1 <= tag.t_s <= word.end_s  # on an acoustic beat of "behind"
    (stroke,) = [(s0, s1) for s0, s1, e in g.strokes(speech, seed=0) if e is tag or e == tag]
    m = g.generate(speech, seed=0)
    w = m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]
    v = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) * m.fps
    tv = (m.t_s[:-1] + m.t_s[1:]) / 2
    win = (tv >= stroke[0]) & (tv <= stroke[1])
    err_s = abs(tv[win][np.argmax(v[win])] - tag.t_s)
    assert err_s <= 0.020, f"tag-to-stroke error {1000 * err_s:.1f} ms"
    # and through the whole CLI: the tag changes the robot's motion, the robot still rests at the end
    plain = _speak(tmp_path, "plain", TAGGED.replace("^gesture(point_away) ", ""))
    tagged = _speak(tmp_path, "tagged", TAGGED)
    assert not np.allclose(plain.q_rad[: min(len(plain.q_rad), len(tagged.q_rad))],
                           tagged.q_rad[: min(len(plain.q_rad), len(tagged.q_rad))])  # fmt: skip
    np.testing.assert_allclose(tagged.q_rad[-1], tagged.rest_q_rad, atol=1e-9)


def test_unknown_tag_is_one_line_error(capsys):
    assert main(["speak", "Look ^gesture(moonwalk) over there."]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "^gesture(moonwalk)" in err and "point_away" in err


def test_user_gesture_file_adds_a_unit(tmp_path, monkeypatch):
    folder = tmp_path / "my_gestures"
    folder.mkdir()
    (folder / "wave.yaml").write_text(
        "units:\n"
        "  wave_hello:\n"
        "    hand: right\n"
        "    priority: 9\n"
        "    triggers: [hello]\n"
        "    prep: {r_abd: 0.6, r_elbow: 0.9}\n"
        "    stroke: {r_abd: 0.9, r_elbow: 1.2, r_twist: -0.6}\n"
        "    meaning: the right hand waves hello\n"
    )
    text = "Hello everyone, it is good to see you."
    plain = _speak(tmp_path, "plain", text)
    waved = _speak(tmp_path, "waved", text, "--gestures", str(folder))
    n = min(len(plain.q_rad), len(waved.q_rad))
    assert not np.allclose(plain.q_rad[:n], waved.q_rad[:n])
    monkeypatch.setenv("ROBOGEST_GESTURES", str(folder))  # the same through the search path
    events = RhythmGenerator().plan(load_speech_input(text=text), seed=0)
    assert any(e.unit == "wave_hello" and e.source == "keyword:hello" for e in events)


def test_bad_gesture_file_names_file_and_key(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("units:\n  wave:\n    stroke: {r_elbw: 0.3}\n")
    assert main(["speak", "Hello there.", "--gestures", str(bad)]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "bad.yaml" in err and "units.wave.stroke.r_elbw" in err and "r_elbow" in err


def test_amount_style_and_gestures_none(tmp_path):
    text = "So here is the thing: we build it, we test it, and we ship it."
    calm = _speak(tmp_path, "calm", text, "--amount", "0.3")
    lively = _speak(tmp_path, "lively", text, "--style", "lively")
    still = _speak(tmp_path, "still", text, "--gestures", "none")
    assert _speech_speed(lively) > 1.3 * _speech_speed(calm)
    assert _speech_speed(still) < 0.5 * _speech_speed(calm)  # idle breathing only


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--amount", "3"], "--amount must be within"),
        (["--amount", "1", "--style", "calm"], "not both"),
        (["--gestures", "/nonexistent/folder"], "no such folder"),
    ],
)
def test_gesture_option_errors(args, match, capsys):
    assert main(["speak", "Hi there.", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and match in err


def test_eval_reports_stroke_sync_on_the_robots_wrist_sites(tmp_path):
    import json

    traj = _speak(tmp_path, "talk", "So here is the thing: we build it, we test it, and we ship it. ... Right?")
    out = tmp_path / "e.json"
    args = ["eval", "--pred", str(tmp_path / "talk.npz"), "--audio", traj.audio_path, "--json", str(out)]
    assert main([*args, "--shifts", "30"]) == 0
    s = json.loads(out.read_text())["results"]["talk"]["beat_sync"]["stroke_sync"]
    assert s["n_peaks"] > 3 and s["n_shifts"] == 30 and 0 <= s["hit"] <= 1 and s["z"] is not None


def test_no_output_overwrites_a_gesture_file_or_the_robots_model(tmp_path, capsys, monkeypatch):
    """An output on one of the files a command reads was written over it (a plot over the gesture YAML, a
    render over the MJCF); it is refused before any work, naming both flags."""
    import shutil

    from robogest.robot.registry import robots_dir

    mine = tmp_path / "g.yaml"
    mine.write_text("units: {}\n")
    for argv in (["speak", "Hi there.", "--gestures", str(mine), "--plot", str(mine)],
                 ["generate", "--text", "Hi there.", "--gestures", str(tmp_path), "--out", str(mine)]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--gestures" in err[0], err
        assert mine.read_text() == "units: {}\n"
    shutil.copytree(robots_dir().parent / "sim" / "humanoid", tmp_path / "sim" / "humanoid")
    (tmp_path / "robots").mkdir()
    shutil.copy(robots_dir() / "humanoid_xl430.yaml", tmp_path / "robots" / "h.yaml")
    model = tmp_path / "sim" / "humanoid" / "humanoid_body.xml"  # included by the scene the YAML names
    before = model.read_bytes()
    for argv in (["robots", "show", str(tmp_path / "robots" / "h.yaml"), "--render", str(model)],
                 ["speak", "Hi.", "--robot", str(tmp_path / "robots" / "h.yaml"), "--save", str(model)]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "humanoid_body.xml" in err[0], err
        assert model.read_bytes() == before
