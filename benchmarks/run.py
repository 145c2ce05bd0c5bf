"""One entry point for every benchmark (not tests): ``make bench`` or ``python benchmarks/run.py``.

Runs each ``bench_*.py`` in its own process (so one's imports and caches do not flatter another), prints
their tables one after the other with wall time and peak memory, and appends every printed line to
``benchmarks/results.csv`` with the git commit, so changes over time are visible.
"""

from __future__ import annotations

import csv
import datetime as dt
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ORDER = [
    "bench_speech.py",
    "bench_pipeline.py",
    "bench_safety.py",
    "bench_bus.py",
    "bench_servo_profile.py",
    "bench_gesticulator.py",
    "bench_s2ag.py",
    "bench_rhythmic.py",
    "bench_generalize.py",
    "bench_meaning.py",
    "bench_live.py",
    "bench_pipecat.py",
    "bench_video.py",
    "bench_say_async.py",
]


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True)
        return out.stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def main(argv: list[str]) -> int:
    wanted = [a for a in argv if not a.startswith("-")]
    scripts = [HERE / s for s in ORDER if (HERE / s).is_file() and (not wanted or any(w in s for w in wanted))]
    commit, stamp = _commit(), dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
    rows = []
    failed = 0
    for script in scripts:
        print(f"\n== {script.name} ==", flush=True)
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        peak_mb = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
        print(proc.stdout.rstrip())
        if proc.returncode != 0:
            failed += 1
            print(f"!! {script.name} failed (exit {proc.returncode}):\n{proc.stderr.strip()[-2000:]}")
        print(f"-- {script.name}: {wall:.1f} s wall, peak RSS so far {peak_mb:.0f} MiB")
        for line in proc.stdout.splitlines():
            if line.strip():
                rows.append([stamp, commit, script.name, f"{wall:.2f}", f"{peak_mb:.0f}", line.strip()])
    out = HERE / "results.csv"
    new = not out.exists()
    with out.open("a", newline="") as f:
        w = csv.writer(f)
        if new:
            w.writerow(["utc", "commit", "script", "wall_s", "peak_rss_mib", "line"])
        w.writerows(rows)
    print(f"\nappended {len(rows)} lines to {out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
