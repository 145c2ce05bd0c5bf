"""The live session through the simulated servo bus and the real vendor SDKs, for both servo families.

Torque stays on between utterances and is off after close; every goal is within limits; an interrupt ends at
rest; SIGINT, SIGTERM and an exception inside the session end at rest with torque off; a streamed utterance
passes the same checks as a batch one.
"""

from __future__ import annotations

import signal
import time

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.live import Robot
from robogest.robot.registry import find_robot
from robogest.safety import JointLimits
from robogest.safety.stages import long_silent_spans, rest_reach_time_s
from robogest.speech import synthesize
from robogest.virtualbus import VirtualBus

ROBOTS = [("humanoid_xl430", "dynamixel"), ("humanoid_sts3215", "feetech")]
FAST = 4.0  # loop seconds per wall second
#: The simulated bus answers from a thread of this process, which a loaded CI machine can starve for longer than
#: the default 0.15 s lost-servo time (and a starved pty has been seen to hand a health read a stale packet);
#: these tests are about the session, not about fault detection (tests/backends covers that).
OPTS = {"time_scale": FAST, "warm_up": False, "backend_options": {"lost_after_s": 1.0, "health_hz": 0}}


@pytest.fixture(autouse=True)
def _scs_end():
    yield
    import scservo_sdk as scs

    scs.SCS_SETEND(0)  # the Feetech SDK keeps its byte order in a global


class Goals:
    """Every goal the control loop sent: ``(loop_s, q (J,))``."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.q: list[np.ndarray] = []

    def __call__(self, t: float, q: np.ndarray) -> None:
        self.t.append(t)
        self.q.append(np.array(q))

    def check(self, robot) -> np.ndarray:
        """Position, velocity, acceleration and jerk limits at the loop period, like a batch trajectory's."""
        q = np.array(self.q)
        dt, tol = float(np.median(np.diff(self.t))), 1e-7  # loop seconds per tick
        assert (q >= robot.q_min_rad - tol).all() and (q <= robot.q_max_rad + tol).all()
        v = np.diff(q, axis=0)
        assert (np.abs(v) <= robot.v_max_rad_s * dt + tol).all()
        a = np.diff(v, axis=0)
        assert (np.abs(a) <= robot.a_max_rad_s2 * dt * dt + tol).all()
        assert (np.abs(np.diff(a, axis=0)) <= robot.j_max_rad_s3 * dt**3 + tol).all()
        return q


def _bus_rest_ok(bus: VirtualBus, robot_name: str, backend) -> None:
    time.sleep(0.05)
    assert not any(s.torque_on for s in bus.servos)
    rec = bus.record()
    goals = rec["goal_ticks"]
    assert np.all(goals >= rec["min_ticks"]) and np.all(goals <= rec["max_ticks"])
    rest_ticks = np.array([bus.servo(int(i)).get("goal") for i in rec["servo_ids"]])
    exp = backend.rad_to_ticks(find_robot(robot_name).rest_q_rad)
    np.testing.assert_allclose(rest_ticks, exp[np.argsort(backend.ids)], atol=2)


def _servo_backend(robot: Robot):
    return robot.loop.backend


@pytest.mark.parametrize(("name", "family"), ROBOTS)
def test_torque_stays_on_between_utterances_and_goes_off_at_rest_on_close(name, family):
    cfg = find_robot(name)
    goals = Goals()
    with VirtualBus(cfg) as bus:
        with Robot(name, backend=family, port=bus.port, on_tick=goals, **OPTS) as robot:
            h1 = robot.say("Hello there!")
            assert h1.done and not h1.interrupted
            assert all(s.torque_on for s in bus.servos)  # between the two utterances: still holding
            types = [e["type"] for e in h1.events]
            for t in ("requested", "first_goal", "started", "audio_start", "done"):
                assert t in types
            assert h1.event("first_goal")["t_monotonic_s"] <= h1.event("done")["t_monotonic_s"]
            time.sleep(0.3)  # idle motion plays
            assert all(s.torque_on for s in bus.servos)
            h2 = robot.say("Nice to meet you.")
            assert h2.done and robot.status()["open"]
            backend = _servo_backend(robot)
        assert not robot.status()["open"]
        _bus_rest_ok(bus, name, backend)
    q = goals.check(cfg)
    assert np.ptp(q, axis=0).max() > 0.1  # it gestured
    np.testing.assert_allclose(q[-1], np.clip(cfg.rest_q_rad, cfg.q_min_rad, cfg.q_max_rad), atol=1e-6)


@pytest.mark.parametrize(("name", "family"), ROBOTS)
def test_streamed_utterance_passes_the_batch_checks(name, family):
    cfg = find_robot(name)
    sp = synthesize("Hello there, how are you? ... I am fine.")
    goals = Goals()
    with VirtualBus(cfg) as bus:
        with Robot(name, backend=family, port=bus.port, on_tick=goals, idle=False, **OPTS) as robot:
            pcm = np.round(sp.audio * 32767).astype(np.int16)
            with robot.stream(sp.sr) as s:
                for i in range(0, len(pcm), 320):  # 20 ms chunks, int16, as a voice agent sends them
                    s.feed(pcm[i : i + 320])
            assert s.wait(60)
            feed = s.planner.feed
            backend = _servo_backend(robot)
        _bus_rest_ok(bus, name, backend)
    types = [e["type"] for e in s.events]
    for t in ("first_chunk", "first_goal", "started", "audio_start", "done"):
        assert t in types
    assert "audio_chunk" in types  # no sound device here: the caller gets the play times
    q = goals.check(cfg)
    assert np.ptp(q, axis=0).max() > 0.1
    # the streamed plan itself: rest held in the long pause, ends at rest (as the batch check_trajectory asks)
    traj = feed.to_trajectory()
    np.testing.assert_allclose(traj.q_rad[-1], cfg.rest_q_rad, atol=1e-9)
    t = np.arange(traj.n_frames) / traj.fps
    spans = s.speech.silent_spans
    silent = np.zeros(traj.n_frames, bool)
    for a, b in spans:
        silent |= (t >= a) & (t < b)
    lim = JointLimits.from_robot(cfg)
    reach = rest_reach_time_s(None, lim, traj.fps)
    long = long_silent_spans(silent, traj.fps, 1.0)
    assert long  # the "..." pause
    for a, b in long:
        k0, k1 = a + int(np.ceil(reach * traj.fps)), b - int(np.ceil(0.4 * traj.fps))
        if k1 > k0:
            np.testing.assert_allclose(traj.q_rad[k0:k1], np.broadcast_to(cfg.rest_q_rad, (k1 - k0, len(cfg.joints))))


def test_interrupt_mid_utterance_glides_to_rest_within_limits_and_idle_resumes():
    name, family = ROBOTS[0]
    cfg = find_robot(name)
    goals = Goals()
    with VirtualBus(cfg) as bus, Robot(name, backend=family, port=bus.port, on_tick=goals, **OPTS) as robot:
        h = robot.say("Hello there! This is a long sentence that will be cut short by the listener.", wait=False)
        deadline = time.monotonic() + 30
        while h.event("started") is None and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.4)  # 1.6 loop seconds into the speech
        r = robot.interrupt()
        assert h.interrupted and h.done and r["at_rest_s"] >= r["interrupt_s"]
        np.testing.assert_allclose(robot.loop.goal_rad, robot.loop.rest_q_rad, atol=1e-4)
        assert all(s.torque_on for s in bus.servos)  # interrupt is not shutdown
        n_at_rest = len(goals.q)
        time.sleep(0.6)  # idle resumes after the delay, fading in from rest
        assert np.abs(np.array(goals.q[n_at_rest:]) - robot.loop.rest_q_rad).max() > 1e-4
    goals.check(cfg)


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "exception"])
@pytest.mark.parametrize(("name", "family"), ROBOTS)
def test_signal_or_exception_inside_the_session_ends_at_rest_with_torque_off(name, family, how):
    cfg = find_robot(name)
    with VirtualBus(cfg) as bus:
        backend = None
        expected = KeyboardInterrupt if how != "exception" else RuntimeError
        with pytest.raises(expected), Robot(name, backend=family, port=bus.port, **OPTS) as robot:
            backend = _servo_backend(robot)
            h = robot.say("Hello there, nice to meet you!", wait=False)
            deadline = time.monotonic() + 30
            while h.event("first_goal") is None and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(0.2)
            if how == "exception":
                raise RuntimeError("bug in the caller")
            signal.raise_signal(getattr(signal, how))
            h.wait(30)  # the signal is raised in here at the latest
        assert backend is not None and not backend.is_connected
        _bus_rest_ok(bus, name, backend)


def test_session_refuses_bad_input_with_one_clear_line():
    with Robot("humanoid_xl430", backend="sim", idle=False, time_scale=FAST, warm_up=False) as robot:
        with pytest.raises(InputError, match="either text to speak"):
            robot.say()
        with pytest.raises(InputError, match="mono"), robot.stream(16000) as s:
            s.feed(np.zeros((320, 2), np.int16))
        assert robot.status()["open"]  # still running
        h = robot.say("Hi.")
        assert h.done
    with pytest.raises(InputError, match="not open"):
        robot.say("Hi.")


@pytest.mark.parametrize("prepare", ["process", "thread"])
def test_an_interrupt_while_a_say_is_still_being_prepared_keeps_it_from_starting(monkeypatch, prepare):
    """A voice agent's barge-in can come before the reply's motion exists: that reply must never start."""
    import threading

    opts = {"idle": False, "audio": False, "time_scale": FAST, "warm_up": False, "prepare": prepare}
    with Robot("humanoid_xl430", backend="sim", **opts) as robot:
        prepare_say = robot.planning.preparer.prepare
        preparing = threading.Event()

        def slow_prepare(*a, **k):
            preparing.set()
            time.sleep(0.3)
            return prepare_say(*a, **k)

        monkeypatch.setattr(robot.planning.preparer, "prepare", slow_prepare)
        box: dict = {}
        t = threading.Thread(target=lambda: box.update(h=robot.say("Let me tell you about it.", wait=False)))
        t.start()
        assert preparing.wait(30)
        robot.interrupt()
        t.join(30)
        h = box["h"]
        assert h.done and h.interrupted and h.event("started") is None and h.event("first_goal") is None
        time.sleep(0.2)
        np.testing.assert_allclose(robot.loop.goal_rad, robot.loop.rest_q_rad, atol=1e-9)
        assert robot.say("Still here.").event("done") is not None  # later utterances play


def test_plans_of_streams_and_the_warm_up_never_share_the_ik_solver_at_once():
    """They share one IK solver and its MuJoCo data; two threads in it at once crashed the process (segfault)."""
    import threading

    with Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=FAST) as robot:
        retarget, inside, worst = robot.planning.ik.retarget, [0], [0]
        count = threading.Lock()

        def counted(*a, **k):
            with count:
                inside[0] += 1
                worst[0] = max(worst[0], inside[0])
            try:
                time.sleep(0.002)  # widen the window a race needs
                return retarget(*a, **k)
            finally:
                with count:
                    inside[0] -= 1

        robot.planning.ik.retarget = counted
        sp = synthesize("One, two, three, four.")
        streams = [robot.stream(sp.sr), robot.stream(sp.sr)]  # the warm-up runs too
        for i in range(0, len(sp.audio), 1600):
            for s in streams:
                s.feed(sp.audio[i : i + 1600])
        for s in streams:
            s.close()
        for s in streams:
            s.wait(60)
    assert worst[0] == 1


def test_a_stream_whose_motion_cannot_start_finishes_its_handle_instead_of_hanging():
    from robogest.errors import SafetyError

    with Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=FAST, warm_up=False) as robot:
        sp = synthesize("Hello.")

        def broken(*a, **k):
            raise SafetyError("the loop is gone (simulated)")

        robot.loop.play = broken
        with pytest.raises(SafetyError, match="simulated"), robot.stream(sp.sr) as s:
            for i in range(0, len(sp.audio), 1600):
                s.feed(sp.audio[i : i + 1600])
                time.sleep(0.01)
            assert s.handle.wait(20)  # done (abandoned), not blocked
            s.wait(20)
        assert s.handle.interrupted


def test_a_signal_as_open_finishes_still_ends_at_rest_with_torque_off(monkeypatch):
    import threading

    from robogest.backends.signals import Interrupted

    start = threading.Thread.start

    def signal_after_warm_up_starts(self):
        start(self)
        if self.name == "robogest-warm-up":
            raise Interrupted(signal.SIGTERM)  # what the signal handler raises in the main thread

    monkeypatch.setattr(threading.Thread, "start", signal_after_warm_up_starts)
    robot = Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=FAST, warm_up=False)
    with pytest.raises(KeyboardInterrupt), robot:
        pass
    assert robot.loop.closed and not robot.loop._thread.is_alive()
    assert robot.loop.backend._torque is False


def test_says_streams_and_interrupts_from_several_threads_never_deadlock_and_end_at_rest():
    """Lock order across the session (an utterance's start, a stream's start, interrupt, idle) under contention:
    every thread finishes, and the last interrupt leaves the robot at rest."""
    import threading

    sp = synthesize("One two.")
    errors: list[BaseException] = []
    with Robot("humanoid_xl430", backend="sim", idle=True, audio=False, time_scale=FAST, warm_up=False) as robot:

        def talk():
            for _ in range(3):
                robot.say("Yes.", wait=False)
                time.sleep(0.05)

        def stream():
            for _ in range(3):
                with robot.stream(sp.sr) as s:
                    for i in range(0, len(sp.audio), 1600):
                        s.feed(sp.audio[i : i + 1600])

        def barge_in():
            for _ in range(6):
                time.sleep(0.08)
                robot.interrupt(wait=False)

        def run(f):
            try:
                f()
            except BaseException as e:  # reported below
                errors.append(e)

        threads = [threading.Thread(target=run, args=(f,)) for f in (talk, stream, barge_in, talk)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert not any(t.is_alive() for t in threads), "a thread is stuck (deadlock?)"
        assert not errors, errors
        r = robot.interrupt()
        assert r["at_rest_s"] is not None
        np.testing.assert_allclose(robot.loop.goal_rad, robot.loop.rest_q_rad, atol=1e-4)


def test_a_replaced_stream_that_fails_later_leaves_the_utterance_playing_now_alone():
    sp = synthesize("This stream is replaced by a say and then its planner fails.")
    with Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=FAST, warm_up=False) as robot:
        s = robot.stream(sp.sr)
        half = len(sp.audio) // 2
        for i in range(0, half, 1600):
            s.feed(sp.audio[i : i + 1600])
        deadline = time.monotonic() + 30
        while s.handle.event("first_goal") is None and time.monotonic() < deadline:
            time.sleep(0.01)
        h = robot.say("Now this.", wait=False)  # replaces the stream's motion once prepared (in the worker)
        assert h.wait_started(60) and h._play is not None

        def broken():
            raise RuntimeError("planner bug (simulated)")

        s.planner.plan = broken
        for i in range(half, len(sp.audio), 1600):
            s.feed(sp.audio[i : i + 1600])
        deadline = time.monotonic() + 30
        while s._error is None and time.monotonic() < deadline:  # the stream's thread meets the bug
            time.sleep(0.01)
        with pytest.raises(RuntimeError, match="simulated"):
            s.wait(30)
        assert h.wait(60) and h.event("done") is not None and not h.interrupted


def test_open_after_close_raises_instead_of_doing_nothing():
    """`Robot.open()` after `close()` returned the closed session silently; every say then failed as not open."""
    robot = Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=FAST, warm_up=False)
    robot.open()
    assert robot.open() is robot  # open twice while open: the same session
    robot.close()
    with pytest.raises(InputError, match=r"this humanoid_xl430 session was closed; .*make a new Robot\(\.\.\.\)"):
        robot.open()
    assert robot.close() is None  # closing again stays a no-op


@pytest.mark.parametrize(("name", "family"), ROBOTS)
def test_torque_lost_between_utterances_ends_the_session_at_rest_and_the_next_say_names_the_servo(name, family):
    """The loop holds the robot between utterances: a servo found limp there (a brownout, another program) stops
    the session like any servo failure (the others glide to rest, torque off) and the next say raises it."""
    from robogest.errors import BackendError

    cfg = find_robot(name)
    sid = cfg.bus.servos["l_shoulder_pitch"].id
    with VirtualBus(cfg) as bus:
        with Robot(name, backend=family, port=bus.port, **OPTS) as robot:
            assert robot.say("Hello there!").done
            backend = _servo_backend(robot)
            time.sleep(0.2)  # idle motion plays
            t_cut = bus.elapsed_s
            bus.inject_now("torqueoff", sid)
            deadline = time.monotonic() + 30
            while robot.status()["open"] and time.monotonic() < deadline:
                time.sleep(0.01)
            with pytest.raises(BackendError, match=rf"^servo id {sid} \(joint l_shoulder_pitch\): torque found off"):
                robot.say("Are you still there?")
        _bus_rest_ok(bus, name, backend)
        rec = bus.record()
    k = list(rec["servo_ids"]).index(sid)
    assert not rec["torque_on"][rec["t_s"] >= t_cut + 0.01, k].any()  # never switched back on


def test_a_finished_utterance_keeps_no_audio_speech_or_planner_alive():
    """The handle of the last utterance stays with the session: it must not hold the stream (its speech, features
    and planner: 65 MB for 300 s) nor, where nothing plays it, the audio (serve grew 100 MB per 300 s stream)."""
    import gc
    import weakref

    sr = 16000
    t = np.arange(2 * sr) / sr
    tone = (0.3 * np.sin(2 * np.pi * 160 * t) * (np.sin(2 * np.pi * 2.5 * t) > -0.3)).astype(np.float32)
    with Robot("humanoid_xl430", backend="sim", idle=False, time_scale=FAST, warm_up=False, audio=False) as robot:
        h = robot.say("Hi there.")
        assert h.done and not robot._audio._buf  # nothing plays it: nothing kept
        st = robot.stream(sr)
        for i in range(0, len(tone), 640):
            st.feed(tone[i : i + 640])
        st.close()
        assert st.wait(60) and robot.status()["utterance"] == st.handle.id
        gone = weakref.ref(st)
        del st
        gc.collect()
        assert gone() is None and not robot._audio._buf
