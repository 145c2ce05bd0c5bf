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
