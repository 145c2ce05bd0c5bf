"""The streaming planner: frames are revised until played and never after, planning cost stays bounded, and the
session plans in its own thread (a voice agent's ``feed`` never waits for a plan)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.generators import make_generator
from robogest.live import Robot
from robogest.live.planner import StreamingPlanner, TrajectoryFeed
from robogest.retarget import DirectionIK
from robogest.robot.registry import find_robot
from robogest.speech import synthesize
from robogest.speech.stream import SpeechStream

ROBOT = "humanoid_xl430"
FAST = {"time_scale": 4.0, "warm_up": False}


@pytest.fixture(scope="module")
def cfg():
    return find_robot(ROBOT)


@pytest.fixture(scope="module")
def tts():
    return synthesize("Hello there, how are you today? ... I am fine, thanks. Shall we start with the first topic?")


# --- the feed ------------------------------------------------------------------------------------------
def test_splice_keeps_sampled_frames_and_continues_from_the_last_kept(cfg, rng):
    feed = TrajectoryFeed(cfg, fps=50.0)
    j = len(cfg.joints)
    old = rng.uniform(-0.1, 0.1, (20, j))
    feed.splice(0, old)
    np.testing.assert_array_equal(feed.q_rad, old)
    feed.sample(0.2)  # the player used frames 10 and 11
    assert feed.first_open == 11
    new = old + 0.05
    n = feed.splice(5, new[5:])
    assert n == 9 and feed.n_frames == 20
    np.testing.assert_array_equal(feed.q_rad[:11], old[:11])  # played frames are final
    # the first new frame continues from frame 10: the plan's offset there decays from its full value
    step_new, step_old = feed.q_rad[11] - feed.q_rad[10], new[11] - new[10]
    np.testing.assert_allclose(step_new, step_old, atol=0.05)
    assert np.abs(feed.q_rad[-1] - new[-1]).max() < 0.05 * np.exp(-8 / 4.2) + 1e-12  # the offset decayed
    assert feed.revised == 9


def test_splice_takes_pinned_frames_as_they_are_and_fills_a_gap_keeping_time(cfg):
    feed = TrajectoryFeed(cfg, fps=50.0)
    j = len(cfg.joints)
    feed.splice(0, np.full((10, j), 0.3))
    feed.sample(0.5)  # the player ran past the end (an underrun): frame 25
    assert feed.underruns == 1
    q = np.zeros((10, j))
    pinned = np.zeros(10, bool)
    pinned[5:] = True
    feed.splice(20, q, pinned=pinned)
    assert feed.n_frames == 30  # frame index is still time * fps
    np.testing.assert_array_equal(feed.q_rad[10:20], np.full((10, j), 0.3))  # the gap held the last pose
    np.testing.assert_array_equal(feed.q_rad[25:], 0.0)  # pinned: exactly as given
    np.testing.assert_allclose(feed.sample(0.5), feed.q_rad[25])


# --- the planner ---------------------------------------------------------------------------------------
def _stream_with_player(cfg, speech, lookahead_s=0.15, words=False, **planner_kw):
    """Feed ``speech`` in 20 ms chunks (with ``words``, each word with the chunk it starts in); a stand-in player
    samples the feed L behind the newest audio.

    Returns the planner and, per frame, its value when the player first used it."""
    st = SpeechStream(speech.sr, lookahead_s=lookahead_s)
    pl = StreamingPlanner(cfg, make_generator("rhythm"), DirectionIK(cfg), st, **planner_kw)
    feed, played = pl.feed, {}
    step = round(0.02 * speech.sr)
    todo = list(speech.words) if words else []
    for i in range(0, len(speech.audio), step):
        ws = []
        while todo and todo[0].start_s < (i + step) / speech.sr:
            w = todo.pop(0)
            ws.append((w.text, w.start_s, w.end_s))
        if st.feed(speech.audio[i : i + step], words=ws):
            pl.plan()
        t = st.received_s - lookahead_s
        if t >= 0 and feed.n_frames:
            feed.sample(t)
            for k in range(feed.first_open):
                played.setdefault(k, feed.q_rad[k].copy())
    st.close()
    pl.plan()
    return pl, played


def test_played_frames_are_never_revised_and_later_ones_are(cfg, tts):
    pl, played = _stream_with_player(cfg, tts)
    feed = pl.feed
    assert feed.closed and feed.underruns == 0
    assert len(played) > 0.8 * tts.duration_s * feed.fps
    for k, q in played.items():
        np.testing.assert_array_equal(feed.q_rad[k], q)
    assert feed.revised > 0  # provisional frames (planned past the newest audio) were rewritten before playing
    np.testing.assert_allclose(feed.q_rad[-1], cfg.rest_q_rad, atol=1e-12)
    q = feed.q_rad
    assert np.all(q >= cfg.q_min_rad) and np.all(q <= cfg.q_max_rad)


def test_plans_share_a_live_plan_that_commits_the_frames_played(cfg, tts):
    """At exactly real time a beat is heard only about 0.15 s before the robot must move for it: the planner tells
    the generator which frames are played, so strokes seen too late for their preparation start from the held
    pose after them, words not heard yet bring expected beats, and gestures under way stay (the invariants
    themselves are tested on the generator, ``test_live_plan_changes_nothing_before_the_committed_frames``)."""
    pl, played = _stream_with_player(cfg, tts, lookahead_s=0.25, words=True)
    live = pl.live
    assert live is not None and live.commit_s == pytest.approx(max(played) / pl.feed.fps, abs=0.05)
    assert any(scale > 0.0 for scale in live.placed.values())  # strokes placed late, from the held pose
    assert live.expected_s  # strokes on beats expected from words not heard yet
    assert live.started  # gestures under way, kept by the plans after
    for k, q in played.items():
        np.testing.assert_array_equal(pl.feed.q_rad[k], q)


def test_each_plan_generates_over_a_bounded_stretch(cfg):
    """Speech with no pause: the generation window slides instead of growing with the utterance."""
    sr = 16000
    t = np.arange(int(14 * sr)) / sr
    syll = (np.sin(2 * np.pi * 4.0 * t) > -0.2).astype(np.float32)  # 4 syllables/s, never silent for long
    audio = (0.3 * np.sin(2 * np.pi * 180 * t) * (0.3 + 0.7 * syll)).astype(np.float32)
    from robogest.speech.stream import stream_speech

    speech = stream_speech(audio, sr)
    seen: list[float] = []
    gen = make_generator("rhythm")
    generate = gen.generate

    def spy(sp, seed=0, **live):
        seen.append(sp.duration_s)
        return generate(sp, seed=seed, **live)

    gen.generate = spy  # type: ignore[method-assign]
    st = SpeechStream(sr)
    pl = StreamingPlanner(cfg, gen, DirectionIK(cfg), st, window_s=4.0)
    for i in range(0, len(speech.audio), 320):
        if st.feed(speech.audio[i : i + 320]):
            pl.plan()
            pl.feed.sample(max(0.0, st.received_s - 0.15))
    assert pl.start_s > 6.0  # the window moved on
    assert max(seen) <= 4.0 + 0.1 + 1.5 + 0.2  # window + one update + the pad + grid rounding


# --- in a session --------------------------------------------------------------------------------------
def test_feed_returns_while_a_plan_is_still_running():
    release, entered = threading.Event(), threading.Event()
    threads: set[str] = set()
    with Robot(ROBOT, backend="sim", idle=False, **FAST) as robot:
        sp = synthesize("Hello there, nice to meet you.")
        s = robot.stream(sp.sr)
        plan = s.planner.plan

        def slow_plan():
            threads.add(threading.current_thread().name)
            entered.set()
            release.wait(30)
            return plan()

        s.planner.plan = slow_plan  # type: ignore[method-assign]
        for i in range(0, len(sp.audio), 320):
            s.feed(sp.audio[i : i + 320])  # all of it, while the first plan is held
        assert entered.wait(30) and not release.is_set()
        release.set()
        s.close()
        assert s.wait(60) and not s.handle.interrupted
    assert threads and threading.current_thread().name not in threads


def test_a_failure_while_planning_stops_the_utterance_and_is_raised_to_the_caller(cfg):
    with Robot(ROBOT, backend="sim", idle=False, **FAST) as robot:
        sp = synthesize("Hello there, nice to meet you.")
        s = robot.stream(sp.sr)
        plan = s.planner.plan

        def failing_plan():
            if s._playing:  # once the motion has started
                raise RuntimeError("planner bug")
            return plan()

        s.planner.plan = failing_plan  # type: ignore[method-assign]
        with pytest.raises(RuntimeError, match="planner bug"):
            for i in range(0, len(sp.audio), 320):
                s.feed(sp.audio[i : i + 320])
                if i == 320 * 20:
                    assert s.handle._attached.wait(30)  # the first plan started the motion
            s.close()
            s.wait(30)
        assert s.handle.interrupted
        robot.loop.resting.wait(30)  # it glides to rest; the session stays open
        np.testing.assert_allclose(robot.loop.goal_rad, robot.loop.rest_q_rad, atol=1e-4)
        assert robot.status()["open"]
        assert robot.say("Still here.").done


def test_speech_and_motion_start_no_earlier_than_the_lookahead_after_the_first_chunk():
    with Robot(ROBOT, backend="sim", idle=True, warm_up=False) as robot:
        sp = synthesize("Hello there.")
        with robot.stream(sp.sr) as s:
            for i in range(0, len(sp.audio), 320):
                s.feed(sp.audio[i : i + 320])
        assert s.wait(30)
        t0 = s.handle.event("first_chunk")["t_monotonic_s"]
        for kind in ("started", "audio_start"):
            assert s.handle.event(kind)["t_monotonic_s"] - t0 >= robot.lookahead_s - 0.011  # one tick of rounding


def test_words_are_checked_in_the_callers_thread():
    with Robot(ROBOT, backend="sim", idle=False, **FAST) as robot, robot.stream(16000) as s:
        with pytest.raises(InputError, match="start_s < end_s"):
            s.feed(np.zeros(320, np.int16), words=[("hello", 0.5, 0.2)])
        s.feed(np.zeros(320, np.int16), words=[("hello", 0.5, 0.7)])
        with pytest.raises(InputError, match="time order"):
            s.feed(np.zeros(320, np.int16), words=[("there", 0.1, 0.3)])
        with pytest.raises(InputError, match=r"a word must be \(text, start_s, end_s\), got \{'text'"):
            s.feed(np.zeros(320, np.int16), words=[{"text": "there", "start": 0.8, "end": 0.9}])
        with pytest.raises(InputError, match="start_s < end_s"):  # a refused message takes none of its words
            s.feed(np.zeros(320, np.int16), words=[("far", 2.0, 2.2), ("bad", 2.5, 2.4)])
        s.feed(np.zeros(320, np.int16), words=[("there", 0.8, 1.0)])  # not "before" the refused 2.0 s


def test_blas_thread_limit_is_the_sessions_own_and_restored_on_close():
    from threadpoolctl import threadpool_info

    def blas() -> list[int]:
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    before = blas()
    with Robot(ROBOT, backend="sim", idle=False, blas_threads=1, **FAST):
        assert all(n == 1 for n in blas())
    assert blas() == before
    with Robot(ROBOT, backend="sim", idle=False, blas_threads=None, **FAST):
        assert blas() == before


def test_a_plan_the_tracker_refuses_stops_the_utterance_instead_of_playing_unchecked_frames(cfg, tts, monkeypatch):
    """Where the tracker cannot continue the motion within the limits, the stream must not fall back to the raw IK
    frames: the refusal is raised (the session then stops the utterance and glides to rest)."""
    from robogest.errors import SafetyError
    from robogest.safety.stage import SafetyStage

    real_track, calls = SafetyStage._track, []

    def refusing_track(self, *args, **kwargs):
        calls.append(1)
        if len(calls) > 1:  # the first plan is tracked; the next is refused
            raise SafetyError("safety: simulated refusal")
        return real_track(self, *args, **kwargs)

    monkeypatch.setattr(SafetyStage, "_track", refusing_track)
    with pytest.raises(SafetyError, match=r"streamed plan \d+ .* glides to rest: safety: simulated refusal"):
        _stream_with_player(cfg, tts)
    assert len(calls) == 2


def test_a_continuous_splice_adds_no_offset_and_a_plain_one_does(cfg):
    j = len(cfg.joints)
    ramp = np.linspace(0.0, 0.2, 20)[:, None] * np.ones(j)
    for continuous, offset in ((True, False), (False, True)):
        feed = TrajectoryFeed(cfg, fps=50.0)
        feed.splice(0, ramp[:10])
        feed.splice(10, ramp[10:], continuous=continuous)
        assert np.array_equal(feed.q_rad, ramp) != offset


def test_the_streamed_feed_keeps_the_velocity_and_acceleration_limits_across_plans(cfg, tts):
    """Each plan resumes the batch path's safety stage from the last frame kept and splices without an offset, so the
    feed (every plan's frames, the end's way to rest included) stays within the limits the batch path keeps
    (before the stage, on this sentence: 126 frames above the acceleration limit, up to 8.2 times)."""
    pl, _ = _stream_with_player(cfg, tts)
    q, dt = pl.feed.q_rad, 1.0 / pl.feed.fps
    d = np.diff(q, axis=0)
    assert np.all(np.abs(d) <= cfg.v_max_rad_s * dt + 1e-9)
    assert np.all(np.abs(np.diff(d, axis=0)) <= cfg.a_max_rad_s2 * dt * dt + 1e-9)
    np.testing.assert_array_equal(q[-1], cfg.rest_q_rad)


def test_the_planner_reads_capabilities_and_refuses_a_batch_only_generator(cfg):
    from robogest.generators.base import Capabilities, Generator

    class BatchOnly(Generator):
        name = "batch_only"

        def generate(self, speech, seed=0):
            raise AssertionError("not called")

    assert BatchOnly.capabilities == Capabilities()  # nothing declared: batch only
    with pytest.raises(InputError, match="'batch_only' cannot stream"):
        StreamingPlanner(cfg, BatchOnly(), DirectionIK(cfg), SpeechStream(16000))
    rhythm = make_generator("rhythm")
    assert rhythm.capabilities.streaming and rhythm.capabilities.live_plan and rhythm.capabilities.rest_windows
    pl = StreamingPlanner(cfg, rhythm, DirectionIK(cfg), SpeechStream(16000))
    assert pl.live is not None
