"""say() off the caller's thread, readiness, per-call body language, one session per robot, a clean exit, and the
asyncio API (robogest.aio) on the simulated robot."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from robogest.errors import BackendError, InputError
from robogest.live import Robot
from robogest.speech import synthesize

ROOT = Path(__file__).resolve().parents[2]
FAST = {"backend": "sim", "idle": False, "audio": False, "time_scale": 4.0, "warm_up": False}
TEXT = "So here is the plan. We walk to the door, then we turn left and wait for the others."


@pytest.mark.slow
@pytest.mark.parametrize("prepare", ["thread", "process"])
def test_say_is_prepared_off_the_callers_thread_and_its_failure_is_raised_by_wait_and_reported_as_an_event(prepare):
    with Robot("humanoid_xl430", prepare=prepare, **FAST) as robot:
        generate, threads = robot.planning.generator.generate, []

        def spy(*a, **k):
            threads.append(threading.current_thread().name)
            return generate(*a, **k)

        robot.planning.generator.generate = spy
        h = robot.say("Hello there.", wait=False)
        assert h.wait(60) and h.event("done") is not None
        # the session's worker, not the caller's thread; or not this process at all
        assert threads == (["robogest-warm-up"] if prepare == "thread" else [])

        bad = robot.say(audio=str(ROOT / "no_such_file.wav"), wait=False)  # queued: returns a handle
        with pytest.raises(InputError, match="no_such_file"):
            bad.wait(60)
        assert bad.done and not bad.interrupted
        assert "no_such_file" in bad.event("error")["message"]
        with pytest.raises(InputError, match="either text"):  # what is wrong with the call itself: at once
            robot.say(wait=False)
        assert robot.say("Still here.").event("done") is not None  # the session goes on


def test_ready_waits_for_the_warm_up_and_wait_ready_reports_it():
    gate = threading.Event()
    robot = Robot("humanoid_xl430", **{**FAST, "warm_up": True})
    warm_up = robot._warm_up
    robot._warm_up = lambda: (gate.wait(60), warm_up())
    with robot:
        assert not robot.ready and not robot.wait_ready(0.1)
        gate.set()
        assert robot.wait_ready(120) and robot.ready
    assert not robot.ready
    with pytest.raises(InputError, match="not open"):
        robot.wait_ready(1)


def _extent(h) -> float:
    q = h.trajectory.q_rad
    return float(np.abs(q - h.trajectory.rest_q_rad).max())


@pytest.mark.slow
def test_per_call_body_language_overrides_the_sessions_for_that_utterance_only():
    with Robot("humanoid_xl430", generator_options={"amount": 1.5}, **FAST) as robot:
        before = robot.say(TEXT, wait=False)
        still = robot.say(TEXT, amount=0.0, wait=False)
        none = robot.say(TEXT, gestures="none", style="lively", wait=False)
        after = robot.say(TEXT, wait=False)
        for h in (before, still, none, after):
            h.wait(120)
        assert _extent(before) > 0.1
        assert _extent(still) < 0.5 * _extent(before) and _extent(none) < 0.5 * _extent(before)
        np.testing.assert_allclose(after.trajectory.q_rad, before.trajectory.q_rad)  # the session's own again
        with robot.stream(16000, amount=0.25) as s:
            assert s.planner.generator.config.amount == 0.25
        with robot.stream(16000) as s:
            assert s.planner.generator.config.amount == 1.5  # streams follow the session's options too
        bad = [
            ({"style": "loud"}, '"style"'),
            ({"amount": 3}, '"amount"'),
            ({"amount": "x"}, '"amount"'),
            ({"gestures": "/no/such/dir"}, '"gestures"'),
            ({"style": "calm", "amount": 1}, "not both"),
        ]
        for kw, field in bad:
            with pytest.raises(InputError, match=field):
                robot.say("Hi.", wait=False, **kw)
            with pytest.raises(InputError, match=field):
                robot.stream(16000, **kw)


def test_a_second_session_on_the_same_robot_is_refused_with_one_line():
    with Robot("humanoid_xl430", **FAST):
        with pytest.raises(BackendError, match=r"robot humanoid_xl430 \(sim\) already has an open session"):
            Robot("humanoid_xl430", **FAST).open()
        with Robot("humanoid_sts3215", **FAST):  # another robot: fine
            pass
    with Robot("humanoid_xl430", **FAST) as again:  # closed: free again
        assert again.status()["open"]


def test_a_second_session_on_the_same_serial_port_is_refused_before_the_bus_is_touched():
    from robogest.robot.registry import find_robot
    from robogest.virtualbus import VirtualBus

    opts = {**FAST, "backend": "dynamixel", "backend_options": {"lost_after_s": 1.0, "health_hz": 0}}
    with VirtualBus(find_robot("humanoid_xl430")) as bus, Robot("humanoid_xl430", port=bus.port, **opts) as robot:
        with pytest.raises(BackendError, match=f"serial port {bus.port} already has an open session"):
            Robot("humanoid_xl430", port=bus.port, **opts).open()
        assert robot.say("Still mine.").event("done") is not None  # the first session is untouched


@pytest.mark.slow
def test_a_script_that_exits_without_close_ends_at_rest_and_prints_no_leak_messages():
    script = (
        "import atexit\n"
        "from robogest import Robot\n"
        "robot = Robot('humanoid_xl430', backend='sim', audio=False, warm_up=False)\n"
        "atexit.register(lambda: print('closed at exit:', robot.loop.closed, flush=True))  # runs after robogest's\n"
        "robot.open()\n"
        "h = robot.say('Hello there, and goodbye.', wait=False)\n"
        "h.wait_started(120)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "closed at exit: True" in out.stdout
    assert "leak" not in out.stderr, out.stderr


# --- asyncio ---------------------------------------------------------------------------------------
async def _ticker(stop: asyncio.Event, late: list[float], period_s: float = 0.01) -> None:
    """The loop's own 10 ms ticker: how late each tick wakes."""
    loop = asyncio.get_running_loop()
    due = loop.time() + period_s
    while not stop.is_set():
        await asyncio.sleep(max(0.0, due - loop.time()))
        late.append(loop.time() - due)
        due += period_s


@pytest.mark.slow
def test_await_say_stream_and_interrupt_never_block_the_event_loop():
    from robogest.aio import AsyncRobot

    sp = synthesize("One, two, three, four, five.")

    async def main() -> dict:
        out: dict = {}
        async with AsyncRobot("humanoid_xl430", **{**FAST, "warm_up": True}) as robot:
            assert robot.ready
            stop, late = asyncio.Event(), []
            ticker = asyncio.ensure_future(_ticker(stop, late))
            out["say"] = await robot.say(TEXT, style="calm")
            stop.set()
            await ticker
            out["late_s"] = max(late)
            h = await robot.say(TEXT, wait=False)
            out["queued_done"] = h.done
            await asyncio.sleep(0.3)
            out["interrupt"] = await robot.interrupt()
            out["interrupted"] = await h.wait(30) and h.interrupted
            async with robot.stream(sp.sr, amount=0.5) as s:
                for i in range(0, len(sp.audio), 1600):
                    await s.feed(sp.audio[i : i + 1600])
                    await asyncio.sleep(0.025)
            out["stream"] = await s.wait(60)
            out["stream_events"] = {e["type"] for e in s.handle.events}
            with pytest.raises(InputError, match="no_such_file"):
                await robot.say(audio=str(ROOT / "no_such_file.wav"))
        out["closed"] = robot.robot.loop.closed
        return out

    out = asyncio.run(main())
    assert out["say"].event("done") is not None
    assert out["late_s"] < 0.15, out["late_s"]  # generous (CI is busy): benchmarks/bench_say_async.py measures it
    assert not out["queued_done"] and out["interrupted"]
    assert out["interrupt"]["at_rest_s"] is not None
    assert out["stream"] and {"first_goal", "done"} <= out["stream_events"]
    assert out["closed"]


def test_a_session_whose_robot_failed_does_not_keep_it_from_being_opened_again():
    """What serve's reopen does after a servo was lost: the dead session holds nothing."""
    with Robot("humanoid_xl430", **FAST) as dead:
        dead.loop.error = BackendError("servo id 3: lost (simulated)")
        with Robot("humanoid_xl430", **FAST) as again:
            assert again.status()["open"]
        dead.loop.error = None


def test_per_call_styles_are_the_clis():
    from robogest.cli.common import STYLES
    from robogest.live.style import STYLES as LIVE

    assert LIVE == STYLES
