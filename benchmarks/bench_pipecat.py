"""Pipecat processor latencies beside ``Robot.stream`` fed directly, on the same audio (simulated robot, real time).

* streamed TTS audio -> first goal: a scripted TTS emits 20 ms ``TTSAudioRawFrame`` s and word-timestamp frames in
  real time through Pipecat's own pipeline and runner into ``RobotGestureProcessor``; from the turn's first audio
  frame reaching the processor to the robot's first goal. Side by side: the same 20 ms chunks and words fed to
  ``Robot.stream`` by a plain thread (first chunk -> first goal);
* interruption -> at rest: an ``InterruptionFrame`` queued mid-utterance -> the control loop's glide to rest done;
  side by side: ``robot.interrupt()`` on a direct stream at the same instants;
* the event loop: how late a 10 ms asyncio ticker ran while the pipeline streamed to the robot (the processor
  must never block it).

Targets (issue 32): first goal p95 <= 300 ms (L = 250 ms included), interruption -> rest <= 500 ms.
"""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np

TEXT = "Hello there! It is really nice to meet you today."
PARAGRAPH = (
    "Good morning everyone, and thank you for coming. Today I want to talk about three things. "
    "First, why robots should move when they speak."
)
TURNS = 10
DELAYS_S = (0.3, 0.6, 0.9, 1.2, 1.5, 1.8)


def pct(x: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(x), q))


def row(what: str, values: list[float], target: str = "", unit: str = "ms") -> None:
    k = 1e6 if unit == "us" else 1e3
    p50, p95, top = pct(values, 50) * k, pct(values, 95) * k, max(values) * k
    print(f"{what:<62} p50 {p50:6.0f} {unit}  p95 {p95:6.0f} {unit} max {top:6.0f} {unit} n={len(values):<3} {target}")


def _rest_done_after(robot, prev, t0: float, timeout_s: float = 10.0) -> float:
    """Seconds from ``t0`` to the end of the control loop's glide to rest begun after ``t0`` (``prev``: the loop's
    rest handle then). The handle is caught as soon as it exists: the idle motion drops it once rest is reached."""
    rest = None
    while rest is None and time.monotonic() - t0 < timeout_s:
        r = robot.loop.resting
        if r is not None and r is not prev:
            rest = r
        else:
            time.sleep(0.001)
    if rest is None or not rest.wait(timeout_s) or "done" not in rest.events:
        return float("nan")
    return rest.events["done"].monotonic_s - t0


def _wait_first_goal(get_handle, timeout_s: float = 30.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        h = get_handle()
        if h is not None and h.event("first_goal") is not None:
            return
        time.sleep(0.005)


async def _ticker(late: list[float], stop: asyncio.Event, period_s: float = 0.01) -> None:
    nxt = time.monotonic() + period_s
    while not stop.is_set():
        await asyncio.sleep(max(0.0, nxt - time.monotonic()))
        late.append(max(0.0, time.monotonic() - nxt))
        nxt += period_s


async def _pipecat_side(robot) -> tuple[list[float], ...]:
    from robogest.integrations.pipecat_scripted import LocalPipeline

    first, rest, late, own = [], [], [], []
    stop = asyncio.Event()
    async with LocalPipeline(robot) as p:
        for name in ("_on_audio", "_on_text", "_end_turn", "_interrupt"):  # the processor's work in the event loop
            setattr(p.gestures, name, _timed(getattr(p.gestures, name), own))
        tick = asyncio.create_task(_ticker(late, stop))
        turns = p.gestures.turns
        for _ in range(TURNS):
            await p.say(TEXT)
            turn = turns[-1]
            while turn.handle is None or not turn.handle.done:
                await asyncio.sleep(0.02)
            goal = turn.handle.event("first_goal")
            first.append(goal["t_monotonic_s"] - turn.first_audio_s if goal else float("nan"))
        stop.set()
        await tick
        for delay in DELAYS_S:
            n = len(turns)
            await p.speak(PARAGRAPH)
            await asyncio.to_thread(_wait_first_goal, lambda n=n: turns[-1].handle if len(turns) > n else None)
            await asyncio.sleep(delay)
            prev, t0 = robot.loop.resting, time.monotonic()
            await p.interrupt()
            rest.append(await asyncio.to_thread(_rest_done_after, robot, prev, t0))
            await asyncio.sleep(0.5)
    return first, rest, late, own


class _StubStream:
    handle = None

    def feed(self, *a, **k) -> None:
        pass

    def close(self) -> None:
        pass


class _StubRobot:
    """Takes the processor's calls and does nothing: the event loop's lateness without the robot's threads."""

    def stream(self, *a, **k) -> _StubStream:
        return _StubStream()

    def interrupt(self, wait: bool = True) -> dict:
        return {}


async def _ticker_with_stub(turns: int = 3) -> list[float]:
    from robogest.integrations.pipecat_scripted import LocalPipeline

    late: list[float] = []
    stop = asyncio.Event()
    async with LocalPipeline(_StubRobot()) as p:
        tick = asyncio.create_task(_ticker(late, stop))
        for _ in range(turns):
            await p.say(TEXT)
        stop.set()
        await tick
    return late


def _timed(fn, into: list[float]):
    def run(*args):
        t = time.perf_counter()
        fn(*args)
        into.append(time.perf_counter() - t)

    return run


def _feed(stream, sp, stop: threading.Event | None = None) -> None:
    """The scripted TTS's schedule: 20 ms int16 chunks in real time, each with the words that start in it."""
    pcm = np.round(np.clip(sp.audio, -1, 1) * 32767).astype("<i2")
    step, words, t0 = round(0.02 * sp.sr), list(sp.words), time.monotonic()
    for k, i in enumerate(range(0, len(pcm), step)):
        if stop is not None and stop.is_set():
            return
        ws = []
        while words and words[0].start_s < (i + step) / sp.sr:
            w = words.pop(0)
            ws.append((w.text, w.start_s, w.end_s))
        stream.feed(pcm[i : i + step].tobytes(), words=ws or None)
        time.sleep(max(0.0, t0 + (k + 1) * 0.02 - time.monotonic()))


def _direct_side(robot) -> tuple[list[float], ...]:
    from robogest.speech import synthesize

    sp, para = synthesize(TEXT), synthesize(PARAGRAPH)
    first, opened, rest = [], [], []
    for _ in range(TURNS):
        t_open = time.monotonic()
        with robot.stream(sp.sr) as s:
            _feed(s, sp)
        s.wait(60)
        h = s.handle
        first.append(h.event("first_goal")["t_monotonic_s"] - h.event("first_chunk")["t_monotonic_s"])
        opened.append(h.event("first_goal")["t_monotonic_s"] - t_open)
    for delay in DELAYS_S:
        s, stop = robot.stream(para.sr), threading.Event()
        feeder = threading.Thread(target=_feed, args=(s, para, stop))
        feeder.start()
        _wait_first_goal(lambda s=s: s.handle)
        time.sleep(delay)
        r = robot.interrupt()
        rest.append(r["at_rest_s"] - r["interrupt_s"])
        stop.set()
        feeder.join()
        time.sleep(0.5)
    return first, opened, rest


def main() -> None:
    try:
        from loguru import logger

        import robogest.integrations.pipecat  # noqa: F401
    except ImportError:
        print("bench_pipecat: skipped: Pipecat is not installed (pip install 'robogest[pipecat]')")
        return
    except Exception as e:  # robogest's refusal of a missing extra
        print(f"bench_pipecat: skipped: {e}")
        return

    from robogest.live import Robot

    logger.remove()  # Pipecat's debug lines
    with Robot("humanoid_xl430", backend="sim", audio=False) as robot:
        robot.wait_ready()
        stub_late = asyncio.run(_ticker_with_stub())
        pc_first, pc_rest, late, own = asyncio.run(_pipecat_side(robot))
        d_first, d_opened, d_rest = _direct_side(robot)
    row("Pipecat: first TTS audio frame -> first goal", pc_first, "target <= 300 ms p95")
    row("Robot.stream direct, same audio: stream() call -> first goal", d_opened, "(same start as above)")
    row("Robot.stream direct: first chunk -> first goal", d_first, "(stream already open)")
    row("Pipecat: InterruptionFrame mid-utterance -> at rest", pc_rest, "target <= 500 ms")
    row("Robot.stream direct: interrupt() mid-utterance -> at rest", d_rest)
    row("Pipecat: a 10 ms asyncio ticker's lateness while streaming", late, "(the whole event loop)")
    row("  same pipeline and TTS, a robot stub (no planning threads)", stub_late)
    row("Pipecat: the processor's own work per frame, in the event loop", own, unit="us")


if __name__ == "__main__":
    main()
