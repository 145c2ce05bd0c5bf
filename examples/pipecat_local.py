"""A full local Pipecat loop with a simulated robot: no cloud keys, no network, a few seconds.

    PYTHONPATH=. python examples/pipecat_local.py        (needs: pip install 'robogest[pipecat]')

The pipeline is ``ScriptedTTS -> RobotGestureProcessor(robot) -> OutputRecorder``, run by Pipecat's own
``PipelineWorker`` and ``WorkerRunner``. In a real agent the scripted TTS is your TTS service and the recorder
your ``transport.output()`` (see docs/voice-agents.md). Turn 1 is spoken to the end; turn 2 is cut short by an
``InterruptionFrame``, as when the user barges in.
"""

from __future__ import annotations

import asyncio
import sys
import time

from loguru import logger  # Pipecat's logger

from robogest import Robot


def report(i: int, turn) -> None:
    h = turn.handle
    goal = h.event("first_goal")
    first = f"{(goal['t_monotonic_s'] - turn.first_audio_s) * 1000:.0f} ms" if goal else "none"
    state = "interrupted" if h.interrupted else ("done" if h.done else "playing")
    print(f"turn {i}: {turn.n_frames} audio frames, first audio -> first goal {first}, {state}")


async def main(robot: Robot) -> None:
    from robogest.integrations.pipecat_scripted import LocalPipeline  # after the logger is set (Pipecat logs)

    async with LocalPipeline(robot) as p:
        await p.say("Hello! I am a robot, and I move my arms while I talk.")
        while not p.gestures.turns[-1].handle.done:  # the motion plays a little behind the audio
            await asyncio.sleep(0.05)
        report(1, p.gestures.turns[-1])

        await p.speak("Let me tell you a long story about servos, safety limits, and gestures.")
        while len(p.gestures.turns) < 2 or p.gestures.turns[-1].handle is None:
            await asyncio.sleep(0.02)
        await asyncio.sleep(1.5)
        t0 = time.monotonic()
        await p.interrupt()  # the user barges in
        while not p.gestures.turns[-1].handle.done:
            await asyncio.sleep(0.01)
        report(2, p.gestures.turns[-1])
        print(f"interruption frame -> utterance interrupted in {(time.monotonic() - t0) * 1000:.0f} ms (the robot"
              f" glides to rest within stop_within_s = {robot.stop_within_s} s)")  # fmt: skip
    print(f"frames through the processor: {len(p.output.frames)}; robot errors: {p.gestures.last_error}")


if __name__ == "__main__":
    logger.remove()
    logger.add(sys.stderr, level="WARNING")
    with Robot("humanoid_xl430", backend="sim", audio=False) as robot:
        asyncio.run(main(robot))
