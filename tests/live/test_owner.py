"""The thread that owns a session's utterance state (robogest.live.owner): messages run in order, in its thread;
call returns or raises what the message did; after stop they run in the caller's thread."""

from __future__ import annotations

import threading

import pytest

from robogest.live.owner import Owner


def test_messages_run_in_order_in_the_owners_thread_and_call_hands_back_results_and_errors():
    owner = Owner("test-owner")
    owner.start()
    seen: list[tuple[int, str]] = []
    try:
        for i in range(50):
            owner.post(lambda i=i: seen.append((i, threading.current_thread().name)))
        assert owner.call(lambda: len(seen)) == 50  # after every message posted before it
        assert [i for i, _ in seen] == list(range(50))
        assert {name for _, name in seen} == {"test-owner"}
        with pytest.raises(ZeroDivisionError):
            owner.call(lambda: 1 / 0)
        assert owner.call(lambda: "still alive") == "still alive"
    finally:
        owner.stop()
    here = threading.current_thread().name
    assert owner.call(threading.current_thread) is threading.current_thread()  # stopped: runs here
    owner.post(lambda: seen.append((99, threading.current_thread().name)))
    assert seen[-1] == (99, here)


def test_a_failing_posted_message_is_reported_and_the_owner_goes_on(capsys):
    owner = Owner("test-owner")
    owner.start()
    try:
        owner.post(lambda: [][1])
        assert owner.call(lambda: 7) == 7
    finally:
        owner.stop()
    assert "state change failed" in capsys.readouterr().err


def test_the_sessions_utterance_state_changes_only_in_its_owner_thread(monkeypatch):
    """say, a stream's start, interrupt and close change what plays and its audio in one thread: no lock needed."""
    import numpy as np

    from robogest.live import Robot

    where: list[str] = []
    with Robot("humanoid_xl430", backend="sim", idle=False, audio=False, time_scale=4.0, warm_up=False) as robot:
        replace = robot._replace_audio
        monkeypatch.setattr(robot, "_replace_audio", lambda out: (where.append(threading.current_thread().name),
                                                                  replace(out))[1])  # fmt: skip
        assert robot.say("Hello there.").event("done") is not None
        h = robot.say("And here is a longer one that will not finish.", wait=False)
        assert h.wait_started(120)
        robot.interrupt()
        with robot.stream(16000) as s:
            t = np.arange(16000) / 16000
            s.feed((0.3 * np.sin(2 * np.pi * 160 * t)).astype(np.float32))
        assert s.wait(60)
    assert len(where) >= 4 and set(where) == {"robogest-session"}, where
