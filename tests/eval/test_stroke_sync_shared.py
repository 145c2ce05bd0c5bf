"""The stroke-sync measure on the real BEAT2 take in ../shared/data (skipped when absent).

A sync measure is only worth reporting if real motion capture, aligned with its own speech, scores above
chance and the same motion shifted by seconds does not.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from robogest.eval.beats import audio_onsets, stroke_sync

pytestmark = pytest.mark.shared
STEM = "beat2/2_scott_0_1_1"
SHIFTS_S = (2, 3, 5, 8, 13, 21, 34)


@pytest.fixture(scope="module")
def take():
    from tests.conftest import SHARED_DATA

    if not (SHARED_DATA / f"{STEM}.npz").is_file():
        pytest.skip(f"{SHARED_DATA / STEM}.* not available")
    from robogest.motion import load_motion
    from robogest.speech import load_speech

    m = load_motion(SHARED_DATA / f"{STEM}.npz")
    sp = load_speech(SHARED_DATA / f"{STEM}.wav", SHARED_DATA / f"{STEM}.TextGrid")
    wrists = m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]
    return wrists, m.fps, audio_onsets(sp.audio, sp.sr), list(sp.silent_spans)


@pytest.mark.xfail(
    strict=True,
    reason="measured z = -0.7 on this take (hit 0.72 vs chance 0.75): librosa's default onsets (4.3/s) are too "
    "dense for this speaker's wrist peaks to stand out; no detector setting in a small grid reached +3",
)
def test_real_motion_capture_scores_above_chance(take):
    w, fps, on, spans = take
    assert stroke_sync(w, fps, on, spans)["z"] >= 3.0


def test_shifted_motion_capture_scores_chance(take):
    w, fps, on, spans = take
    zs = np.array([stroke_sync(np.roll(w, round(s * fps), axis=0), fps, on, spans)["z"] for s in SHIFTS_S])
    assert np.median(np.abs(zs)) < 1.5, zs
    assert np.abs(zs).max() < 2.0, zs


def test_eval_json_reports_stroke_sync(take, tmp_path):
    from robogest.cli.main import main
    from tests.conftest import SHARED_DATA

    out = tmp_path / "e.json"
    args = ["eval", "--pred", str(SHARED_DATA / f"{STEM}.npz"), "--audio", str(SHARED_DATA / f"{STEM}.wav")]
    args += ["--transcript", str(SHARED_DATA / f"{STEM}.TextGrid"), "--json", str(out), "--shifts", "40"]
    assert main(args) == 0
    (res,) = json.loads(out.read_text())["results"].values()
    s = res["beat_sync"]["stroke_sync"]
    assert {"hit", "chance", "z"} <= set(s) and 0 <= s["chance"] <= 1 and s["n_shifts"] == 40
    assert "pmb_wrist_peaks" not in res["beat_sync"]
    # PMB and BeatAlign see onset beats only, never the front-end's pseudo-beats
    assert res["beat_sync"]["n_audio_beats"] < 200
