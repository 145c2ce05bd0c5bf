"""say() without blocking (issue 32 §2), on the simulated robot, one process:

* ``say(paragraph, wait=False)``: how long the call holds the caller, for a 120-word paragraph (target <= 5 ms);
* first say after ``wait_ready()`` vs later says of other sentences of the same length: call -> first goal (the
  warm-up the session documents should leave no difference beyond noise);
* an asyncio loop's own 10 ms ticker during ``await robot.say(...)`` (AsyncRobot): how late its ticks wake, p50 /
  p95 / max (target: never more than 20 ms late).

Numbers depend on the machine's load: the run prints ``os.getloadavg()`` with them.
"""

from __future__ import annotations

import asyncio
import os
import sys
import time

import numpy as np

#: 120 words.
PARAGRAPH = (
    "Good morning everyone, and thank you for coming today. I want to talk about three things that matter to "
    "anyone who builds a robot that speaks. First, why a robot should move when it talks: people read the hands "
    "and the head as much as they hear the words, and a still robot sounds flat. Second, how the rhythm of speech "
    "shapes a gesture, with strokes that land on the stressed syllables and rests that follow the pauses. Third, "
    "what we can build together next year, from friendly guides in a museum to patient helpers in a hospital ward. "
    "So please ask questions whenever you like, and let us begin with the very first one right now, together. "
    "Thank you."
)
SENTENCE = "Hello there! It is really nice to meet you today."
#: Sentences of one length, each said once: the first after ready against the others (a repeated sentence would
#: flatter the later says with the per-word caches of speech and gesture planning).
SENTENCES = (
    "The weather looks fine, so we could walk down to the harbour.",
    "Do you remember where we parked the blue car last night?",
    "Tomorrow morning I will show you the new garden behind the house.",
    "Please put the heavy boxes on the table next to the window.",
    "We should call your sister before the shops close this evening.",
)


def stats(what: str, values: list[float], target: str = "") -> None:
    a = np.asarray(values) * 1000
    print(
        f"{what:<52} p50 {np.percentile(a, 50):7.2f} ms  p95 {np.percentile(a, 95):7.2f} ms  max {a.max():7.2f} ms"
        f"  n={len(a):<3} {target}"
    )


def latency(h) -> float:
    return h.event("first_goal")["t_monotonic_s"] - h.event("requested")["t_monotonic_s"]


def bench_blocking(n: int = 10) -> None:
    from robogest.live import Robot

    with Robot("humanoid_xl430", backend="sim", audio=False) as robot:
        t0 = time.perf_counter()
        robot.wait_ready()
        print(f"open -> ready (warm-up: idle motion, TTS, generator, planner): {time.perf_counter() - t0:.2f} s")
        first = latency(robot.say(SENTENCES[0]))
        later = [latency(robot.say(text)) for text in SENTENCES[1:]]
        stats("first say after ready: call -> first goal", [first])
        stats(
            "later says (other sentences): call -> first goal",
            later,
            f"(first - p50: {first - np.median(later):+.3f} s)",
        )
        calls = []
        for _ in range(n):
            t0 = time.perf_counter()
            h = robot.say(PARAGRAPH, wait=False)
            calls.append(time.perf_counter() - t0)
            robot.interrupt()
            h.wait(120)
        stats(f"say(120 words, wait=False) returns ({len(PARAGRAPH.split())} words)", calls, "target <= 5 ms")


async def _ticker(stop: asyncio.Event, late: list[float], period_s: float = 0.01) -> None:
    loop = asyncio.get_running_loop()
    due = loop.time() + period_s
    while not stop.is_set():
        await asyncio.sleep(max(0.0, due - loop.time()))
        late.append(loop.time() - due)
        due += period_s


async def bench_asyncio() -> None:
    from robogest.aio import AsyncRobot

    stop, idle = asyncio.Event(), []  # the machine's own noise: the same ticker with no robot
    ticker = asyncio.ensure_future(_ticker(stop, idle))
    await asyncio.sleep(10.0)
    stop.set()
    await ticker
    stats("asyncio 10 ms ticker lateness, no robot (baseline)", idle)
    async with AsyncRobot("humanoid_xl430", backend="sim", audio=False) as robot:
        stop, late = asyncio.Event(), []
        ticker = asyncio.ensure_future(_ticker(stop, late))
        for text in (SENTENCE, PARAGRAPH):
            await robot.say(text)
        stop.set()
        await ticker
        stats("asyncio 10 ms ticker lateness during await say()", late, "target: max <= 20 ms")


def main() -> None:
    print(f"load average (1 min) {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; python {sys.version.split()[0]}")
    bench_blocking()
    asyncio.run(bench_asyncio())


if __name__ == "__main__":
    main()
