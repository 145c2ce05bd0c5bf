"""Semantic choice by sentence embedding (``--semantic embedding``, learn extra): time per sentence.

Issue 13's target is at most 50 ms per sentence. The encoder is loaded once (as the generator keeps it);
each sentence is then embedded and compared with the units' meanings, one at a time, as the generator does.

``.venv/bin/python benchmarks/bench_meaning.py``
"""

from __future__ import annotations

import os
import time

import numpy as np

SENTENCES = (
    "we should all stand together on this",
    "it was a really enormous building",
    "I have no idea what happened there",
    "look at the mountains over on the left",
    "first we cook and then we eat",
    "nobody ever wants to go back",
    "please take a seat and relax",
    "the results were much better than we expected last year",
    "so what do you think we should do about the whole situation now",
    "thanks",
)


def main() -> None:
    from robogest.errors import MissingDependencyError
    from robogest.generators.lexicon import default_repertoire
    from robogest.generators.meaning import MeaningChooser

    t0 = time.perf_counter()
    try:
        chooser = MeaningChooser(default_repertoire())
    except MissingDependencyError as e:
        print(f"skipped: {e}")
        return
    load_s = time.perf_counter() - t0
    times = []
    for _ in range(5):
        for s in SENTENCES:
            t = time.perf_counter()
            chooser.choose(s)
            times.append(time.perf_counter() - t)
    ms = 1000 * np.asarray(times)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; encoder load {load_s:.1f} s")
    print(f"per sentence ({len(ms)} calls, 1-13 words): median {np.median(ms):.1f} ms, p95 "
          f"{np.percentile(ms, 95):.1f} ms, max {ms.max():.1f} ms; target <= 50 ms")  # fmt: skip


if __name__ == "__main__":
    main()
