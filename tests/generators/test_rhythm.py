from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.eval.beats import stroke_peaks
from robogest.generators import DEFAULT_GENERATOR, make_generator
from robogest.generators.acoustic import acoustic_beats
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


def test_acoustic_beats_judge_rises_against_the_audio_heard(rng):
    """A live stream pads the speech not heard yet with zeros: with ``heard_s`` they change no beat and no
    prominence. Counted, they pull the quiet level down, so a weak rise passes as a beat in a stream's plan and
    not in the whole utterance."""
    sr = 16000
    beats = [0.4, 0.9, 1.5, 2.1, 2.6]
    noise = (0.002 * rng.standard_normal(3 * sr)).astype(np.float32)
    a = syllable_bursts(3.0, beats, sr) + 0.05 * syllable_bursts(3.0, [1.2], sr) + noise  # 1.2 s: a weak rise
    base = acoustic_beats(a, sr)
    assert len(base.t_s) == len(beats)
    padded = np.concatenate([a, np.zeros(2 * sr, np.float32)])
    got = acoustic_beats(padded, sr, heard_s=3.0)
    np.testing.assert_allclose(got.t_s, base.t_s, atol=1e-9)
    np.testing.assert_allclose(got.prominence, base.prominence, atol=0.02)
    assert len(acoustic_beats(padded, sr).t_s) == len(beats) + 1  # what heard_s prevents


@pytest.mark.parametrize("lead_s", [0.0, 0.1])
def test_strokes_lead_their_beats(lead_s):
    """The wrist-speed peak of each stroke falls ``stroke_lead_s`` before its acoustic beat (within one 50 fps
    frame), and the motion has no speed peak off the led beats: preparations peak the same lead before
    earlier beats or are left out."""
    beats = [1.0, 1.45, 2.5, 2.9, 4.0, 4.4, 5.5]
    sp = build_speech(7.0, beats, [])
    cfg = RhythmConfig(fps=50.0, gesture_rate=3.0, head_beat_prob=0.0, sway_rad=0.0, drift_m_s=0.0)
    g = RhythmGenerator(cfg, stroke_lead_s=lead_s)
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
        assert g.stroke_peak_s(e) == pytest.approx(e.t_s - lead_s)
        assert abs(peak_t - (e.t_s - lead_s)) <= 0.021, f"{e.unit} peak at {peak_t:.3f}, beat at {e.t_s:.3f}"
    w = m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]
    peaks = stroke_peaks(w, m.fps)
    peaks = peaks[peaks < 6.5]  # the final retraction to rest is not a gesture
    assert peaks.size >= len(strokes)
    assert np.abs(peaks[:, None] - (found[None] - lead_s)).min(axis=1).max() <= 0.03, peaks


def test_stroke_lead_out_of_range_is_input_error():
    from robogest.errors import InputError

    with pytest.raises(InputError, match=r"stroke_lead_s must be within \[0, 0.5\] s, got -0.1"):
        RhythmGenerator(stroke_lead_s=-0.1)


def test_drift_loudness_out_of_range_is_input_error():
    from robogest.errors import InputError

    with pytest.raises(InputError, match=r"drift_loudness must be within \[0, 1\], got 1.5"):
        RhythmGenerator(drift_loudness=1.5)


@pytest.mark.parametrize(("k", "lo", "hi"), [(0.0, 0.8, 1.25), (0.6, 2.5, 6.0)])
def test_drift_speed_follows_the_voice_loudness(k, lo, hi):
    """With no gestures planned the wrists move by the drift alone: steady without ``drift_loudness``, faster
    while the voice is loud (syllables every 0.25 s in 1-4 s) than while it is quiet (5-7 s) with it
    (full loudness gives 1 + k, none 1 - k times ``drift_m_s``: 4x for k = 0.6)."""
    sp = build_speech(8.0, list(np.arange(1.0, 4.0, 0.25)), [])
    g = RhythmGenerator(fps=50.0, gesture_rate=0.0, head_beat_prob=0.0, sway_rad=0.0, drift_loudness=k)
    assert g.plan(sp) == []
    m = g.generate(sp, seed=0)
    v = wrist_speed_cm_s(m)
    t = m.t_s[:-1]
    loud, quiet = v[(t > 1.8) & (t < 3.5)].mean(), v[(t > 5.0) & (t < 7.0)].mean()
    assert quiet > 5.0  # never still while speaking
    assert lo < loud / quiet < hi, (loud, quiet)


def test_drift_speeds_up_on_every_beat_and_gives_the_turn_back():
    """With no gestures planned, the wrists' drift has a speed peak on each beat (``stroke_lead_s`` before
    it), 1.5 times as fast as without ``drift_beat_rad`` at least, and the turn is given back: well after the
    last beat the motion is the same as without it (so a live plan's beats change the motion only near them)."""
    from robogest.eval.beats import stroke_peaks
    from robogest.generators.rhythm import DRIFT_RETURN_S, DRIFT_RETURN_WIDTH_S

    sp = build_speech(8.0, [1.0, 1.8, 2.6, 3.4], [])
    kw = dict(fps=100.0, gesture_rate=0.0, head_beat_prob=0.0, sway_rad=0.0, drift_loudness=0.0)
    g, flat = RhythmGenerator(**kw), RhythmGenerator(**kw, drift_beat_rad=0.0)
    assert g.plan(sp) == []
    beats = g.beats(sp).t_s - g.config.stroke_lead_s
    assert len(beats) >= 3
    m, m0 = g.generate(sp, seed=0), flat.generate(sp, seed=0)

    def wrists(motion):
        return motion.positions()[:, [motion.skeleton.index("l_wrist"), motion.skeleton.index("r_wrist")]]

    peaks = stroke_peaks(wrists(m), m.fps)
    assert all(np.min(np.abs(peaks - b)) < 0.03 for b in beats), (peaks, beats)
    k = np.round(beats * m.fps).astype(int)
    v, v0 = wrist_speed_cm_s(m)[k], wrist_speed_cm_s(m0)[k]
    assert np.all(v > 1.5 * v0), (v, v0)  # the circle alone is not faster there
    after = m.t_s > beats.max() + DRIFT_RETURN_S + 6 * DRIFT_RETURN_WIDTH_S
    np.testing.assert_allclose(wrists(m)[after], wrists(m0)[after], atol=1e-6)


def test_drift_settings_out_of_range_are_input_errors():
    from robogest.errors import InputError

    with pytest.raises(InputError, match=r"drift_beat_rad must be within \[0, 1\] rad.*got 1.5 and 0.05"):
        RhythmGenerator(drift_beat_rad=1.5)
    with pytest.raises(InputError, match=r"live_drift_m_s must be within \[0, 1\] m/s, got -0.1"):
        RhythmGenerator(live_drift_m_s=-0.1)
    with pytest.raises(InputError, match=r"^drift_m_s must be within \[0, 1\] m/s, got 2"):
        RhythmGenerator(drift_m_s=2)


def test_preparation_leads_an_earlier_beat_and_is_slower_than_its_stroke():
    from robogest.generators.rhythm import GestureEvent

    beats = np.array([1.0, 1.5, 3.0, 3.5])
    g = RhythmGenerator(RhythmConfig(fps=50.0, sway_rad=0.0, drift_m_s=0.0))
    events = [GestureEvent(1.5, "beat_large_both", 1.5, "beat"), GestureEvent(3.5, "beat_medium_both", 1.5, "beat")]
    track, placed = g._arm_track(events, [], 5.0, beats)
    assert [e.t_s for _, _, e in placed] == [1.5, 3.5]
    t = np.arange(0, 5.0, 0.005)
    w = g_positions(track.sample(t))
    v = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) / 0.005  # (T-1,) m/s
    tv = t[:-1] + 0.0025
    # The first stroke leaves rest: no earlier beat leaves room for a slow enough preparation, so it
    # starts straight from rest; the second one's preparation peaks stroke_lead_s before the beat at 3.0 s.
    lead = g.config.stroke_lead_s
    for prep_beat, (s0, s1, _) in zip((3.0,), placed[1:], strict=True):
        prep = (tv > 2 * prep_beat - s0) & (tv < s0)
        stroke = (tv >= s0) & (tv <= s1)
        assert abs(tv[prep][np.argmax(v[prep])] - (prep_beat - lead)) < 0.03  # the preparation leads its beat
        assert v[prep].max() < v[stroke].max()  # and slower than the stroke


def g_positions(dofs: np.ndarray) -> np.ndarray:
    """Wrist positions ``(T, 2, 3)`` m of a DOF track."""
    from robogest.motion.skeleton import CANONICAL

    p = CANONICAL.forward_kinematics(dofs_to_rotations(dofs), np.zeros((len(dofs), 3)))
    return p[:, [CANONICAL.index("l_wrist"), CANONICAL.index("r_wrist")]]


def test_keywords_pick_semantic_units(speech_with_pause):
    events = RhythmGenerator().plan(speech_with_pause, seed=0)
    picked = {(e.source.split(":")[1], e.unit) for e in events if e.source.startswith("keyword:")}
    assert ("you", "point_forward") in picked
    assert ("big", "spread_both") in picked
    assert {("no", "negation_sweep"), ("no", "shake")} <= picked  # arms and head both say no
    assert ("this", "frame_both") not in picked  # 0.6 s after "you": lower priority, too close
    assert not any(u == "self_point" for _, u in picked)  # a plain "I" is no reason to point at oneself
    # "you" at 1.2–1.4 s takes the acoustic beat of its syllable at 1.25 s.
    assert [e.t_s for e in events if e.source == "keyword:you"] == pytest.approx([1.25], abs=0.03)


def test_semantic_units_by_priority_not_first_come():
    """'this' (frame, priority 3) comes first, 'everything' (spread, priority 4) 0.5 s later: the spread wins."""
    beats = [0.5, 1.0, 1.5]
    words = [("this", 0.45, 0.7), ("is", 0.75, 0.9), ("everything", 0.95, 1.4)]
    sp = build_speech(2.5, beats, [], words)
    sem = [e for e in RhythmGenerator().plan(sp, seed=0) if e.source.startswith("keyword:")]
    assert [e.unit for e in sem] == ["spread_both"]


def test_no_unit_twice_in_a_row_within_10_s(rng):
    beats = list(np.round(np.arange(0.5, 30.0, 0.45), 2))
    sp = build_speech(30.5, beats, [])
    for seed in range(3):
        arms = [e for e in RhythmGenerator(gesture_rate=3.0).plan(sp, seed=seed) if e.source == "beat"]
        arms = [e for e in arms if RhythmGenerator().repertoire.units[e.unit].channel == "arms"]
        assert len(arms) > 30
        for a, b in itertools.pairwise(arms):
            assert a.unit != b.unit, (a, b)


def test_repertoire_has_the_listed_units():
    units = RhythmGenerator().repertoire.units
    assert len(units) >= 25
    listed = ["palms_up_open", "frame_both", "spread_both", "size_small", "count_one", "count_two", "list_next"]
    listed += ["negation_sweep", "self_point", "point_forward", "point_away", "nod", "head_tilt", "shrug"]
    assert set(listed) <= set(units)
    beats = [u for u in units.values() if u.kind == "beat" and u.channel == "arms"]
    assert {u.size for u in beats} == {"small", "medium", "large"} and {u.hand for u in beats} >= {"left", "right"}


def test_statistical_interpreter_matches_target_frequencies(rng):
    rep = RhythmGenerator().repertoire
    names = rep.beat_units
    target = np.array([rep.units[n].frequency for n in names])
    target /= target.sum()
    counts = np.zeros(len(names))
    for _ in range(3000):
        counts[rep.next_beat_unit(counts, 0.6, rng)] += 1
    freq = counts / counts.sum()
    assert (freq > 0.01).all()  # every unit is used
    assert np.abs(freq - target).max() < 0.12


def test_amplitude_follows_prominence():
    sp = build_speech(4.0, [1.0, 2.5], [])
    loud = syllable_bursts(4.0, [2.5])  # the second syllable 20 dB louder than the first
    sp = dataclasses.replace(sp, audio=0.1 * syllable_bursts(4.0, [1.0]) + loud)
    events = [e for e in RhythmGenerator(gesture_rate=3.0).plan(sp, seed=1) if e.source == "beat"]
    amp = sorted((e.t_s, e.amplitude) for e in events if RhythmGenerator().repertoire.units[e.unit].channel == "arms")
    assert len(amp) == 2 and amp[1][1] > amp[0][1]


def test_wrist_speed_cap(speech_with_pause):
    g = RhythmGenerator(fps=100.0, sway_rad=0.0, drift_m_s=0.0, max_wrist_speed_m_s=1.2)
    v = wrist_speed_cm_s(g.generate(speech_with_pause, seed=0))
    assert 60 < v.max() <= 121  # it gestures, and no move is faster than the cap (1% for discretisation)


def wrist_accel_m_s2(motion) -> np.ndarray:
    pos = motion.positions()
    w = pos[:, [motion.skeleton.index("l_wrist"), motion.skeleton.index("r_wrist")]]  # (T, 2, 3)
    return np.linalg.norm(np.diff(w, n=2, axis=0), axis=-1).max(axis=1) * motion.fps**2  # (T-2,)


@pytest.mark.parametrize("seed", [0, 3])
def test_wrist_accel_cap_lengthens_moves_but_keeps_the_strokes(speech_with_pause, seed):
    kw = dict(fps=100.0, sway_rad=0.0, drift_m_s=0.0)
    capped = RhythmGenerator(**kw, max_wrist_accel_m_s2=8.0)
    free = RhythmGenerator(**kw, max_wrist_accel_m_s2=None)
    assert wrist_accel_m_s2(free.generate(speech_with_pause, seed=seed)).max() > 12.0
    assert wrist_accel_m_s2(capped.generate(speech_with_pause, seed=seed)).max() <= 8.0 * 1.05  # path curvature
    assert len(capped.strokes(speech_with_pause, seed=seed)) >= 3


def test_wrist_accel_cap_must_be_positive():
    with pytest.raises(InputError, match="max_wrist_accel_m_s2 must be above 0"):
        RhythmGenerator(max_wrist_accel_m_s2=0.0)


def test_joint_limits_option_slows_every_move_to_what_the_body_can_do():
    beats = [1.0, 1.45, 2.5, 2.9, 4.0, 4.4, 5.5]
    sp = build_speech(7.0, beats, [])
    a_max = 12.0
    g = RhythmGenerator(fps=100.0, sway_rad=0.0, drift_m_s=0.0, head_beat_prob=0.0, max_joint_accel_rad_s2=a_max)
    m = g.generate(sp, seed=0)
    free = RhythmGenerator(fps=100.0, sway_rad=0.0, drift_m_s=0.0, head_beat_prob=0.0).generate(sp, seed=0)
    assert g.strokes(sp, seed=0)  # it still gestures, on the beats

    def peak_accel(motion) -> float:
        q = motion.rotations[:, :, 1:]  # quaternion vector parts ~ half-angles for small rotations
        return float(np.abs(np.diff(q, n=2, axis=0)).max() * motion.fps**2 * 2)

    assert peak_accel(m) < peak_accel(free)


def test_plan_of_a_partial_utterance_is_a_prefix_of_the_whole_plan():
    """For streaming: beat decisions are drawn beat by beat, so planning the speech heard so far gives the
    same events, up to the last beat heard, as planning the whole utterance."""
    beats = list(np.round(np.arange(0.5, 12.0, 0.4), 2))
    whole = build_speech(12.0, beats, [])
    part = build_speech(6.0, [b for b in beats if b < 6.0], [])
    g = RhythmGenerator()
    a = [e for e in g.plan(whole, seed=5) if e.t_s < 5.8]
    b = [e for e in g.plan(part, seed=5) if e.t_s < 5.8]
    assert len(a) > 5 and a == b


def test_live_plan_changes_nothing_before_the_committed_frames():
    """A stream hears a beat only about 0.15 s before the robot must move for it: a stroke first seen after its
    preparation should have started goes straight from the held pose, shortened to fit, so the frames already
    played stay as they were; later plans, with later commits, keep it as placed."""
    from robogest.generators.rhythm import GestureEvent, LivePlan

    beats = np.array([1.0, 1.5, 3.0, 3.5])
    g = RhythmGenerator(RhythmConfig(fps=50.0, sway_rad=0.0, drift_m_s=0.0))
    e1, e2 = GestureEvent(1.5, "beat_large_both", 1.5, "beat"), GestureEvent(3.5, "beat_medium_both", 1.5, "beat")
    t = np.arange(0, 5.0, 0.005)
    offline = g._arm_track([e1, e2], [], 5.0, beats)[0].sample(t)
    live = LivePlan(commit_s=0.0)
    g._arm_track([e1], [], 5.0, beats[:2], live)  # the first stroke, seen in time: prepared as offline
    live.commit_s = 3.3
    before = g._arm_track([e1], [], 5.0, beats[:3], live)[0].sample(t)
    track, placed = g._arm_track([e1, e2], [], 5.0, beats, live)
    after = track.sample(t)
    past = t < live.commit_s
    np.testing.assert_allclose(before[t < 2.0], offline[t < 2.0])
    assert np.abs(offline[past] - before[past]).max() > 0.05  # offline prepares the second stroke before 3.3 s
    np.testing.assert_allclose(after[past], before[past])
    s0, s1, e = placed[-1]
    assert e == e2 and s0 >= live.commit_s
    v = np.linalg.norm(np.diff(g_positions(after), axis=0), axis=-1).max(axis=1) / 0.005  # (T-1,) m/s
    tv = t[:-1] + 0.0025
    stroke = (tv >= s0) & (tv <= s1)
    assert abs(tv[stroke][np.argmax(v[stroke])] - (3.5 - g.config.stroke_lead_s)) < 0.03  # still on its beat
    live.commit_s = 3.45
    np.testing.assert_allclose(g._arm_track([e1, e2], [], 5.0, beats, live)[0].sample(t), after)
    fresh = g._arm_track([e1, e2], [], 5.0, beats, LivePlan(commit_s=3.45))[1]
    assert fresh == []  # seen this late, neither stroke can start after the committed frames: both skipped


def test_live_plan_keeps_a_gesture_the_robot_has_started():
    """A later plan hears more and may choose otherwise at a beat whose gesture is already under way (its
    prominence judged against louder speech, the random choices after a changed beat): a live plan keeps the
    started gesture, so the frames being played are not undone; gestures not started yet may still change."""
    from robogest.generators.rhythm import GestureEvent, LivePlan

    g = RhythmGenerator(RhythmConfig(fps=50.0, sway_rad=0.0, drift_m_s=0.0))
    arms = {n for n, u in g.repertoire.units.items() if u.channel == "arms"}
    beats = np.array([1.0, 1.5, 3.0, 3.5])
    e1, e2 = GestureEvent(1.5, "beat_large_both", 1.5, "beat"), GestureEvent(3.5, "beat_medium_both", 1.5, "beat")
    live = LivePlan(commit_s=1.2)
    first = g._arm_track([e1, e2], [], 5.0, beats, live)[0]
    assert list(live.started) == [1.5]  # e1's preparation started before the next plan; e2's has not
    # the next plan puts another unit near e1's beat and drops e2
    other = GestureEvent(1.52, "beat_small_r", 1.0, "beat")
    events = live.keep_started([other], arms, 0.0, 5.0)
    assert events == [e1]
    t = np.arange(0, 2.2, 0.01)  # e1's gesture (e2's preparation starts later)
    live.commit_s = 1.3
    np.testing.assert_allclose(g._arm_track(events, [], 5.0, beats, live)[0].sample(t), first.sample(t))
    assert (
        np.abs(g._arm_track([other], [], 5.0, beats, LivePlan(commit_s=1.3))[0].sample(t) - first.sample(t)).max()
        > 0.05
    )
    # a window that starts later sees it on its own clock; one that ends before it does not
    assert live.keep_started([], arms, 1.0, 5.0) == [dataclasses.replace(e1, t_s=0.5)]
    assert live.keep_started([other], arms, 0.0, 1.4) == [other]


def test_beats_add_the_stressed_syllables_the_onset_detector_missed():
    """When words are known, a word's stressed syllable with no acoustic beat near it is a beat (issue 13: strokes
    on stressed syllables), one a stroke can take; a live plan (``stressed=False``) expects these instead, and a
    stream's speech gets them only for the syllables heard."""
    from robogest.generators.rhythm import HEARD_AFTER_S, STRESS_NEAR_S, STRESS_PROMINENCE
    from robogest.speech.stress import stress_fraction

    words = [("table", 0.45, 0.8), ("about", 1.5, 1.94)]
    at = 1.5 + stress_fraction("about") * 0.44  # 'ɐ b ˈaʊ t'
    near = 0.45 + stress_fraction("table") * 0.35  # 't ˈeɪ b əl': by the acoustic beat at 0.5 s
    sp = build_speech(3.0, [0.5], [], words)
    g = RhythmGenerator(gesture_rate=3.0)
    acoustic = g.beats(sp, stressed=False)
    assert np.abs(acoustic.t_s - near).min() < STRESS_NEAR_S and np.abs(acoustic.t_s - at).min() > STRESS_NEAR_S
    ab = g.beats(sp)
    np.testing.assert_allclose(ab.t_s, np.sort([*acoustic.t_s, at]), atol=1e-9)  # "table" has its acoustic beat
    assert ab.prominence[np.isclose(ab.t_s, at)] == pytest.approx([STRESS_PROMINENCE])
    assert any(np.isclose(e.t_s, at) for _, _, e in g.strokes(sp, seed=0))
    not_yet = dataclasses.replace(sp, heard_s=at + HEARD_AFTER_S - 0.01)
    assert not np.any(np.isclose(g.beats(not_yet).t_s, at))
    assert np.any(np.isclose(g.beats(dataclasses.replace(sp, heard_s=at + HEARD_AFTER_S + 0.01)).t_s, at))


def test_live_plan_expects_a_beat_in_each_word_not_heard_yet():
    """Words reach a stream with the chunk they start in, about 0.1 s before the beat they bring is heard: a
    live plan expects it on the word's stressed syllable (eSpeak NG's lexicon, placed by the word's phonemes)
    until that is heard, or ``WORD_BEAT_S`` after the start of a word with none, and keeps an expected beat that
    got a stroke when the heard one comes (the stroke has started)."""
    from robogest.generators.rhythm import STRESS_BEAT_S, WORD_BEAT_S, LivePlan
    from robogest.speech.stress import stress_fraction

    words = [("one", 0.45, 0.8), ("two", 0.95, 1.3), ("about", 1.96, 2.4), ("the", 2.5, 2.6)]
    at = 1.96 + stress_fraction("about") * 0.44 + STRESS_BEAT_S  # 'ɐ b ˈaʊ t': half-way through the word
    assert at > 1.96 + WORD_BEAT_S + 0.1
    heard = dataclasses.replace(build_speech(3.0, [0.5, 1.0], [], words), heard_s=1.9)
    g = RhythmGenerator()
    live = LivePlan()
    ab, expected = g._expected_beats(g.beats(heard, stressed=False), heard, live)
    assert expected == {round(at, 3), round(2.5 + WORD_BEAT_S, 3)}
    np.testing.assert_allclose(ab.t_s, [*g.beats(heard, stressed=False).t_s, at, 2.5 + WORD_BEAT_S], atol=1e-9)
    later = dataclasses.replace(heard, heard_s=2.1)  # the word's start is heard, its stressed syllable not yet
    assert round(at, 3) in g._expected_beats(g.beats(later, stressed=False), later, LivePlan())[1]
    whole = build_speech(3.0, [0.5, 1.0, at + 0.05, 2.55], [], words)
    heard_now = g._expected_beats(g.beats(whole, stressed=False), whole, live)[1]
    assert heard_now == set()  # heard now, and no stroke was placed on it
    live.expected_s.add(round(at, 3))
    ab = g._expected_beats(g.beats(whole, stressed=False), whole, live)[0]
    assert np.sum(np.abs(ab.t_s - at - 0.05) < 0.12) == 1 and np.any(np.isclose(ab.t_s, at))


def test_a_live_plan_speeds_its_drift_up_only_where_the_speed_up_comes_after_the_played_frames(monkeypatch):
    """A live plan speeds the drift up on a beat only if the speed-up rises after the frames played
    (``commit_s``), heard or expected (here the heard beats at 0.5 and 1.0 s, the stressed syllable of "about"
    and the start of "the"), with ``live_drift_m_s``; a speed-up that has started stays in later plans, whatever
    they hear. Its drift keeps a steady radius (mid loudness): it plans frames beyond the audio heard, whose
    loudness it cannot know. Offline: every beat, with ``drift_m_s``, and a radius that follows the voice."""
    from robogest.generators.rhythm import LIVE_DRIFT_RISE_WIDTHS, LivePlan

    words = [("one", 0.45, 0.8), ("two", 0.95, 1.3), ("about", 1.96, 2.4), ("the", 2.5, 2.6)]
    heard = dataclasses.replace(build_speech(3.0, [0.5, 1.0], [], words), heard_s=1.9)
    g = RhythmGenerator(fps=50.0)
    c = g.config
    rise_s = c.stroke_lead_s + LIVE_DRIFT_RISE_WIDTHS * c.drift_beat_s
    calls = []
    sway = g._sway

    def spy(t, rests, rng, loud, t0_s, beats_s, drift_m_s):
        calls.append((np.asarray(beats_s), drift_m_s, np.asarray(loud)))
        return sway(t, rests, rng, loud, t0_s, beats_s, drift_m_s)

    monkeypatch.setattr(g, "_sway", spy)
    ab, expected = g._expected_beats(g.beats(heard, stressed=False), heard, LivePlan())
    acoustic = [b for b in ab.t_s if round(b, 3) not in expected]
    assert len(expected) == 2 and len(acoustic) == 2 and abs(acoustic[0] - 0.5) < 0.06

    def drift_beats(commit_s: float) -> np.ndarray:
        live.commit_s = commit_s
        g.generate(heard, seed=0, live=live)
        beats_s, speed, loud = calls[-1]
        assert speed == c.live_drift_m_s == 0.3
        np.testing.assert_array_equal(loud, 0.5)
        return beats_s

    live = LivePlan(replan_s=0.1)
    # the first beat's speed-up rises in the next 0.1 s: it is kept from now on
    np.testing.assert_allclose(drift_beats(acoustic[0] - rise_s - 0.05), sorted([*acoustic, *expected]), atol=1e-3)
    # later, the second acoustic beat comes too late; the first stays though its rise is now played
    np.testing.assert_allclose(drift_beats(acoustic[1] - rise_s + 0.01), sorted([acoustic[0], *expected]), atol=1e-3)
    # a beat a plan no longer hears stays, and blocks a new one within 0.12 s of it
    first, second = sorted(expected)
    live.drift_s.add(first - 0.05)
    np.testing.assert_allclose(drift_beats(1.0), [acoustic[0], first - 0.05, second], atol=1e-3)
    g.generate(heard, seed=0)
    beats_s, speed, loud = calls[-1]
    assert speed == c.drift_m_s == 0.45 and np.ptp(loud) > 0.5
    np.testing.assert_allclose(beats_s, g.beats(heard).t_s)


def test_the_wrist_path_cache_stays_bounded_and_changes_nothing(monkeypatch):
    """A live session runs for hours and its late strokes start from any held pose: the cache is capped, and an
    evicted entry computed again gives the same motion."""
    from robogest.generators.rhythm import timeline as rhythm  # the module whose cache size the generator reads

    sp = build_speech(8.0, list(np.arange(0.6, 7.5, 0.3)), [])
    unbounded = RhythmGenerator()
    full = unbounded.generate(sp, seed=3).rotations
    assert len(unbounded._fk_cache) > 5
    monkeypatch.setattr(rhythm, "FK_CACHE_SIZE", 5)
    gen = RhythmGenerator()
    np.testing.assert_array_equal(gen.generate(sp, seed=3).rotations, full)
    assert len(gen._fk_cache) == 5
