"""The Pipecat processor inside Pipecat's own pipeline and runner (no network): a scripted TTS stand-in emits real
audio and word-timestamp frames in real time into ``RobotGestureProcessor`` and a simulated robot.

Checks behaviour, not timings (those are in benchmarks/bench_pipecat.py): motion starts after the first audio,
the robot is back at rest after an interruption frame, every frame leaves the processor unchanged and in order,
word timings reach the robot's stream, and a missing extra is refused with the install line.
"""

from __future__ import annotations

import asyncio
import importlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robogest.errors import MissingDependencyError

ROOT = Path(__file__).resolve().parents[2]
TEXT = "Hello there, it is really nice to meet you today."
PARAGRAPH = (
    "Good morning everyone, and thank you for coming. Today I want to talk about three things. "
    "First, why robots should move when they speak."
)


@pytest.fixture(scope="module")
def robot():
    pytest.importorskip("pipecat")
    from robogest.live import Robot

    # No idle motion: at rest means at the rest pose. No warm-up: the first plan is slower, which no check here
    # depends on (a loaded machine took a minute to warm up).
    with Robot("humanoid_xl430", backend="sim", idle=False, audio=False, warm_up=False) as r:
        yield r


def _at_rest(robot) -> bool:
    goal = robot.status()["goal_rad"]
    return goal is not None and bool(np.allclose(goal, robot.config.rest_q_rad, atol=1e-3))


@pytest.mark.slow
def test_a_turn_streams_audio_and_words_into_the_robot_and_every_frame_passes_unchanged(robot):
    from pipecat.frames.frames import TTSAudioRawFrame, TTSTextFrame

    from robogest.integrations.pipecat_scripted import LocalPipeline

    async def main():
        async with LocalPipeline(robot) as p:
            await p.say(TEXT)
            turn = p.gestures.turns[-1]
            t0 = time.monotonic()
            while (turn.handle is None or not turn.handle.done) and time.monotonic() - t0 < 60:
                await asyncio.sleep(0.05)
            return p, turn

    p, turn = asyncio.run(main())
    sent, out = p.tts.sent, p.output.frames
    assert len(p.gestures.turns) == 1 and p.gestures.last_error is None
    # Every frame the TTS sent reached the output: the same objects, in the same order, bytes untouched.
    passed = [f for f in out if any(f is s for s in sent)]
    assert len(passed) == len(sent) and all(a is b for a, b in zip(passed, sent, strict=True))
    audio = [f for f in sent if isinstance(f, TTSAudioRawFrame)]
    sp = asyncio.run(p.tts.speech(TEXT))
    pcm = np.round(np.clip(sp.audio, -1, 1) * 32767).astype("<i2").tobytes()
    assert b"".join(f.audio for f in audio) == pcm and turn.n_frames == len(audio)
    # The robot moved, after the first audio, and finished the turn (not interrupted).
    h = turn.handle
    assert h.event("first_goal") is not None, [e["type"] for e in h.events]
    assert h.event("first_goal")["t_monotonic_s"] > turn.first_audio_s
    assert h.event("done") is not None and not h.interrupted
    # The word-timestamp frames became the stream's words, at their times (pts relative to the first audio).
    words = turn.stream.speech.words
    n_words = sum(isinstance(f, TTSTextFrame) for f in sent)
    assert [w.text for w in words] == [w.text for w in sp.words] and len(words) == n_words
    np.testing.assert_allclose([w.start_s for w in words], [w.start_s for w in sp.words], atol=0.15)


@pytest.mark.slow
def test_an_interruption_frame_brings_the_robot_to_rest(robot):
    from robogest.integrations.pipecat_scripted import LocalPipeline

    async def main():
        async with LocalPipeline(robot) as p:
            await p.speak(PARAGRAPH)
            t0 = time.monotonic()
            while time.monotonic() - t0 < 60:  # until the robot moves
                turn = p.gestures.turns[-1] if p.gestures.turns else None
                if turn is not None and turn.handle is not None and turn.handle.event("first_goal") is not None:
                    break
                await asyncio.sleep(0.02)
            moving, t1 = False, time.monotonic()
            while time.monotonic() - t1 < 0.8:  # into the utterance: the robot gestures
                moving = moving or not _at_rest(robot)
                await asyncio.sleep(0.01)
            t_int = time.monotonic()
            await p.interrupt()
            while not _at_rest(robot) and time.monotonic() - t_int < 10:
                await asyncio.sleep(0.01)
            rest_s = time.monotonic() - t_int
            await asyncio.sleep(0.3)
            return p, turn, moving, rest_s, _at_rest(robot)

    p, turn, moving, rest_s, still = asyncio.run(main())
    print(f"interruption frame -> at rest (polled): {rest_s * 1000:.0f} ms")
    assert moving, "the robot never left rest before the interruption: nothing was checked"
    assert still, f"not at rest {rest_s:.1f} s after the interruption frame"
    assert turn.handle.interrupted
    assert p.gestures.last_error is None


def test_a_missing_pipecat_is_refused_with_the_install_line(monkeypatch):
    for name in ("pipecat", "pipecat.frames", "pipecat.frames.frames", "pipecat.processors",
                 "pipecat.processors.frame_processor"):  # fmt: skip
        monkeypatch.setitem(sys.modules, name, None)  # import of it fails as if not installed
    monkeypatch.delitem(sys.modules, "robogest.integrations.pipecat", raising=False)
    from robogest.extras import install_command

    with pytest.raises(MissingDependencyError, match=re.escape(install_command("pipecat"))):
        importlib.import_module("robogest.integrations.pipecat")
    monkeypatch.delitem(sys.modules, "robogest.integrations.pipecat", raising=False)


@pytest.mark.slow
def test_the_local_example_runs():
    pytest.importorskip("pipecat")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pipecat_local.py")], env=env, cwd=ROOT,
                       capture_output=True, text=True, timeout=600)  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    assert "turn 1:" in r.stdout and "interrupted" in r.stdout, r.stdout


class _FakeRobot:
    def __init__(self) -> None:
        self.interrupts = 0

    def interrupt(self, wait: bool = True) -> dict:
        self.interrupts += 1
        return {}


class _Handle:
    def __init__(self, done: bool) -> None:
        self.done = done


def test_an_interruption_moves_the_robot_only_while_a_turn_plays():
    pytest.importorskip("pipecat")
    from robogest.integrations.pipecat import RobotGestureProcessor

    robot = _FakeRobot()
    proc = RobotGestureProcessor(robot)
    proc._w_interrupt()  # nothing said yet: the idle robot is left alone (a user speaking first)
    proc._moving = _Handle(done=True)
    proc._w_interrupt()  # the last turn has finished
    assert robot.interrupts == 0
    proc._moving = _Handle(done=False)
    proc._w_interrupt()
    assert robot.interrupts == 1


def test_words_the_stream_would_refuse_are_left_out():
    pytest.importorskip("pipecat")
    from robogest.integrations.pipecat import _usable, _word_s

    words = [("—", 0.0, 0.2), ("Hello,", 0.1, 0.1 + _word_s("Hello,")), ("...", 0.5, 0.6), ("there", 0.6, 0.9)]
    assert [w[0] for w in _usable(words)] == ["Hello,", "there"]
    assert 0.15 <= _word_s("a") < _word_s("hello") < _word_s("extraordinarily") <= 0.6


def test_multichannel_audio_is_mixed_down_for_the_robot_only():
    pytest.importorskip("pipecat")
    from robogest.integrations.pipecat import _mono_int16

    stereo = np.array([[100, 300], [-50, -150], [7, 9]], dtype="<i2").tobytes()
    np.testing.assert_array_equal(_mono_int16(stereo, 2), [200, -100, 8])
    assert _mono_int16(stereo, 1) is stereo  # mono bytes go as they are
