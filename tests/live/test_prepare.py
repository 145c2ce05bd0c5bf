"""Says prepared in a child process (robogest.live.prepare): the same results as in a thread, its failures on the
handle, a dead child restarted, and no child outliving its session (close, a crash, Ctrl-C)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robogest.errors import BackendError, InputError
from robogest.live import Robot
from robogest.live.prepare import ProcessPreparer, SayPreparer, SayRequest
from robogest.robot.registry import find_robot

ROOT = Path(__file__).resolve().parents[2]
FAST = {"backend": "sim", "idle": False, "audio": False, "time_scale": 4.0, "warm_up": False}


def _gone(pid: int, timeout_s: float = 30.0) -> bool:
    """The process ``pid`` has exited (and is not a zombie of ours) within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        stat = Path(f"/proc/{pid}/stat")
        if stat.exists() and stat.read_text().split(")")[-1].split()[0] == "Z":
            return True  # exited; its parent (a killed test script) is gone, init reaps it
        time.sleep(0.1)
    return False


@pytest.mark.slow
def test_the_child_process_prepares_a_say_bit_for_bit_as_the_thread_does():
    from threadpoolctl import threadpool_limits

    config = find_robot("humanoid_xl430")
    text = "Well, ^start(beat_small_r) here we go: one, two and three!"
    req = SayRequest(text=text, generator_options={"amount": 1.2})
    child = ProcessPreparer(config, blas_threads=1)
    child.start()
    try:
        there = child.prepare(req)
    finally:
        child.close()
    with threadpool_limits(limits=1, user_api="blas"):  # as the session (and the child) limit them
        here = SayPreparer(config).prepare(req)
    assert there.sr == here.sr
    assert np.array_equal(there.audio, here.audio)
    assert np.array_equal(there.trajectory.q_rad, here.trajectory.q_rad)
    assert np.array_equal(there.trajectory.silent, here.trajectory.silent)
    assert there.trajectory.q_rad.shape[0] > 50


@pytest.mark.slow
def test_failures_in_the_child_are_the_same_exceptions_on_the_handle_and_a_dead_child_is_restarted(capfd):
    with Robot("humanoid_xl430", **FAST) as robot:
        child = robot.planning.preparer
        assert isinstance(child, ProcessPreparer)
        bad_tag = robot.say("Hello ^nosuchtag there.", wait=False)
        with pytest.raises(InputError, match="nosuchtag"):
            bad_tag.wait(120)
        missing = robot.say(audio=str(ROOT / "no_such_file.wav"), wait=False)
        with pytest.raises(InputError, match="no_such_file"):
            missing.wait(60)
        assert "no_such_file" in missing.event("error")["message"]

        pid = child.pid
        assert pid is not None
        long = robot.say("This one is long enough to be prepared for a while. " * 20, wait=False)
        time.sleep(0.5)  # it is being prepared
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(BackendError, match="preparation process died"):
            long.wait(120)
        assert robot.say("Still here.").event("done") is not None  # a new child took over
        assert child.restarts == 1 and child.pid != pid
        os.kill(child.pid, signal.SIGKILL)  # dead between says: restarted before the next one
        child._proc.wait(30)
        assert robot.say("And again.").event("done") is not None
        assert child.restarts == 2
        last = child.pid
    assert _gone(last)  # close() ends it
    err = capfd.readouterr().err
    assert err.count("say-preparation process died") == 2  # once per death


def test_the_session_prepares_in_a_thread_when_asked_and_refuses_an_unknown_mode():
    with Robot("humanoid_xl430", prepare="thread", **FAST) as robot:
        assert isinstance(robot.planning.preparer, SayPreparer)
        with pytest.raises(InputError, match="nosuchtag"):
            robot.say("Hello ^nosuchtag there.")
    with pytest.raises(InputError, match="prepare"):
        Robot("humanoid_xl430", prepare="fork", **FAST)


@pytest.mark.slow
def test_ready_includes_the_childs_first_say():
    with Robot("humanoid_xl430", **{**FAST, "warm_up": True}) as robot:
        assert robot.wait_ready(180)
        child = robot.planning.preparer
        assert isinstance(child, ProcessPreparer)
        assert child.served == 1  # the warm-up say: the first real one pays no imports


_SCRIPT = """
import os, sys, time
from robogest import Robot
robot = Robot('humanoid_xl430', backend='sim', audio=False, idle=False)
with robot:
    robot.wait_ready(180)
    print(robot.planning.preparer.pid, flush=True)
    h = robot.say('Here is a long story that is still being prepared when the end comes. ' * 10, wait=False)
    time.sleep(0.3)
    if sys.argv[1] == 'crash':
        os._exit(3)
    time.sleep(600)
"""


@pytest.mark.slow
@pytest.mark.parametrize("how", ["crash", "ctrl-c"])
def test_the_child_never_outlives_its_session(how):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(
        [sys.executable, "-c", _SCRIPT, how], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        start_new_session=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        child_pid = int(proc.stdout.readline())
        if how == "ctrl-c":
            time.sleep(0.5)
            os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole process group
        proc.wait(120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert _gone(child_pid), f"the preparation process {child_pid} outlived its session"
    assert proc.returncode != 0
