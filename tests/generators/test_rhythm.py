from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robogest.eval.beats import stroke_peaks
from robogest.generators import DEFAULT_GENERATOR, make_generator
from robogest.generators import lexicon as lx
from robogest.generators.poses import REST, dofs_to_rotations
from robogest.generators.rhythm import RhythmConfig, RhythmGenerator
from tests.generators.conftest import build_speech, syllable_bursts


def wrist_speed_cm_s(motion) -> np.ndarray:
    pos = motion.positions()
    w = pos[:, [motion.skeleton.index("l_wrist"), motion.skeleton.index("r_wrist")]]  # (T, 2, 3)
    return np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) * motion.fps * 100  # (T-1,)


def test_default_is_rhythm():
    assert DEFAULT_GENERATOR == "rhythm"
    assert isinstance(make_generator("rhythm"), RhythmGenerator)


def test_unknown_generator_is_input_error():
    from robogest.errors import InputError

    with pytest.raises(InputError, match=r"unknown generator 'nope'; choose one of .*rhythm"):
        make_generator("nope")


def test_shape_and_frame_rate(speech_with_pause):
    m = RhythmGenerator().generate(speech_with_pause, seed=0)
    assert m.fps == 20.0 and m.n_frames == speech_with_pause.n_frames
    m50 = RhythmGenerator(fps=50.0).generate(speech_with_pause)
    assert m50.n_frames == 400


def test_deterministic_with_seed(speech_with_pause):
    g = RhythmGenerator()
    a, b = g.generate(speech_with_pause, seed=3), g.generate(speech_with_pause, seed=3)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    c = g.generate(speech_with_pause, seed=4)
    assert not np.allclose(a.rotations, c.rotations)


def test_wrists_at_rest_in_long_silent_periods(speech_with_pause):
    g = RhythmGenerator(fps=50.0)
    m = g.generate(speech_with_pause, seed=0)
    v = wrist_speed_cm_s(m)
    rest_pos = m.skeleton.forward_kinematics(dofs_to_rotations(REST[None]), m.root_pos_m[:1])[0]
    pos = m.positions()
    t = m.t_s
    windows = g.rest_windows(speech_with_pause)
    assert len(windows) == 3  # leading, middle and trailing pauses are all long enough
    for a, b in speech_with_pause.silent_spans:
        if b - a <= 1.0 and a > 0:
            continue
        # The hold window of the silent-period hint: blend in after retract_s, leave rest_lead_s early.
        t0 = a if a == 0 else a + g.config.retract_s
        t1 = b if b >= speech_with_pause.duration_s else b - g.config.rest_lead_s
        inside = (t[:-1] >= t0) & (t[1:] <= t1)
        assert inside.sum() > 5
        assert v[inside].max() < 1.0, f"wrist moves at {v[inside].max():.2f} cm/s inside silence {a}-{b}"
        np.testing.assert_allclose(pos[1:][inside], np.broadcast_to(rest_pos, pos[1:][inside].shape), atol=1e-9)


def test_all_silence_gives_rest_only():
    sp = build_speech(3.0, [], [(0.0, 3.0)])
    m = RhythmGenerator().generate(sp)
    assert wrist_speed_cm_s(m).max() < 1e-9
    assert RhythmGenerator().plan(sp) == []


def test_strokes_land_on_beats():
    """The wrist-speed peak of each stroke falls on its acoustic beat (within one 50 fps frame), and the
    motion has no speed peak off the beats: preparations are centred on earlier beats or left out."""
    beats = [1.0, 1.45, 2.5, 2.9, 4.0, 4.4, 5.5]
    sp = build_speech(7.0, beats, [])
    g = RhythmGenerator(RhythmConfig(fps=50.0, gesture_rate=3.0, head_beat_prob=0.0, sway_rad=0.0))
    found = g.beats(sp).t_s
    np.testing.assert_allclose(found, beats, atol=0.03)  # the detector finds each syllable's onset
    strokes = g.strokes(sp, seed=0)
    assert len(strokes) >= 3
    assert set(e.t_s for _, _, e in strokes) <= set(found)
    m = g.generate(sp, seed=0)
    v = wrist_speed_cm_s(m)
    tv = (m.t_s[:-1] + m.t_s[1:]) / 2
    for s0, s1, e in strokes:
        win = (tv >= s0) & (tv <= s1)
        peak_t = tv[win][np.argmax(v[win])]
        assert abs(peak_t - e.t_s) <= 0.021, f"{e.unit} peak at {peak_t:.3f}, beat at {e.t_s:.3f}"
    w = m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]
    peaks = stroke_peaks(w, m.fps)
    peaks = peaks[peaks < 6.5]  # the final retraction to rest is not a gesture
    assert peaks.size >= len(strokes)
    assert np.abs(peaks[:, None] - found[None]).min(axis=1).max() <= 0.03, peaks


def test_preparation_is_centred_on_an_earlier_beat_and_slower_than_its_stroke():
    from robogest.generators.rhythm import GestureEvent

    beats = np.array([1.0, 1.5, 3.0, 3.5])
    g = RhythmGenerator(RhythmConfig(fps=50.0, sway_rad=0.0))
    events = [GestureEvent(1.5, "beat_large_both", 1.5, "beat"), GestureEvent(3.5, "beat_medium_both", 1.5, "beat")]
    track, placed = g._arm_track(events, [], 5.0, beats)
    assert [e.t_s for _, _, e in placed] == [1.5, 3.5]
    t = np.arange(0, 5.0, 0.005)
    w = g_positions(track.sample(t))
    v = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) / 0.005  # (T-1,) m/s
    tv = t[:-1] + 0.0025
    # The first stroke leaves rest: no earlier beat leaves room for a slow enough preparation, so it
    # starts straight from rest; the second one's preparation is centred on the beat at 3.0 s.
    for prep_beat, (s0, s1, _) in zip((3.0,), placed[1:], strict=True):
        prep = (tv > 2 * prep_beat - s0) & (tv < s0)
        stroke = (tv >= s0) & (tv <= s1)
        assert abs(tv[prep][np.argmax(v[prep])] - prep_beat) < 0.03  # the preparation peaks on its beat
        assert v[prep].max() < v[stroke].max()  # and slower than the stroke


def g_positions(dofs: np.ndarray) -> np.ndarray:
    """Wrist positions ``(T, 2, 3)`` m of a DOF track."""
    from robogest.motion.skeleton import CANONICAL

    p = CANONICAL.forward_kinematics(dofs_to_rotations(dofs), np.zeros((len(dofs), 3)))
    return p[:, [CANONICAL.index("l_wrist"), CANONICAL.index("r_wrist")]]


def test_keywords_pick_semantic_units(speech_with_pause):
    events = RhythmGenerator().plan(speech_with_pause, seed=0)
    by_word = {e.source.split(":")[1]: e.unit for e in events if e.source.startswith("keyword:")}
    assert by_word["you"] == "point_forward"
    assert by_word["big"] == "spread_both"
    assert by_word["no"] == "shake"
    assert by_word["i"] == "self_point"
    assert by_word["so"] == "palms_up_open"
    # "you" at 1.2–1.4 s takes the acoustic beat of its syllable at 1.25 s.
    assert [e.t_s for e in events if e.source == "keyword:you"] == pytest.approx([1.25], abs=0.03)


def test_statistical_interpreter_matches_target_frequencies(rng):
    counts = np.zeros(len(lx.ARM_LEXEMES))
    prev = None
    for _ in range(3000):
        k = lx.next_lexeme(prev, counts, 0.6, rng)
        counts[k] += 1
        prev = k
    freq = counts / counts.sum()
    assert (freq > 0.02).all()  # every lexeme is used
    assert np.abs(freq - lx.LEXEME_FREQ).max() < 0.12


def test_amplitude_follows_prominence():
    sp = build_speech(4.0, [1.0, 2.5], [])
    loud = syllable_bursts(4.0, [2.5])  # the second syllable 20 dB louder than the first
    sp = dataclasses.replace(sp, audio=0.1 * syllable_bursts(4.0, [1.0]) + loud)
    events = [e for e in RhythmGenerator(gesture_rate=3.0).plan(sp, seed=1) if e.source == "beat"]
    amp = sorted((e.t_s, e.amplitude) for e in events if lx.UNITS[e.unit].channel == "arms")
    assert len(amp) == 2 and amp[1][1] > amp[0][1]


def test_wrist_speed_cap(speech_with_pause):
    g = RhythmGenerator(fps=100.0, sway_rad=0.0, max_wrist_speed_m_s=1.2)
    v = wrist_speed_cm_s(g.generate(speech_with_pause, seed=0))
    assert 60 < v.max() <= 121  # it gestures, and no move is faster than the cap (1% for discretisation)
