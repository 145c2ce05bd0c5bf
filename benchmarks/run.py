"""One entry point for every benchmark (not tests): ``make bench`` or ``python benchmarks/run.py``.

Runs every benchmark in :data:`BENCHES` (all ``bench_*.py`` the docs list), each in its own process (so one's
imports and caches do not flatter another), prints their tables one after the other with wall time and peak
memory, and appends every printed line to ``benchmarks/results.csv`` with the git commit, so changes over time are
visible. The four long ones run with a quick parameter set unless ``--full`` is given (their documented
measurement: minutes to tens of minutes each); one that needs ``../shared/data`` is skipped with one line when
that folder is absent.

Usage: ``python benchmarks/run.py [--full] [NAME ...]`` (NAME: part of a script name, e.g. ``video``).
"""

from __future__ import annotations

import csv
import datetime as dt
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
SHARED_DATA = HERE.parent.parent / "shared" / "data"
BEAT2_TAKE = SHARED_DATA / "beat2" / "2_scott_0_1_1"
#: Where bench_first_run.py keeps its venv between quick runs (the first run builds it: minutes, from pip's
#: indexes; later runs reinstall only the wheel, and still time a first ``robogest speak`` on an empty numba cache).
FIRST_RUN_VENV = Path.home() / ".cache" / "robogest" / "bench-first-run-venv"


@dataclass(frozen=True)
class Bench:
    """One benchmark script and the arguments ``run.py`` gives it."""

    script: str
    quick: tuple[str, ...] = ()  #: arguments of a plain run (``make bench``)
    full: tuple[str, ...] | None = None  #: arguments with ``--full`` (the docs' measurement), when they differ
    shared: bool = False  #: needs ``../shared/data``


BENCHES = [
    Bench("bench_speech.py"),
    Bench("bench_pipeline.py"),
    Bench("bench_safety.py"),
    Bench("bench_bus.py"),
    Bench("bench_servo_profile.py"),
    Bench("bench_governor.py"),
    Bench("bench_gesticulator.py"),
    Bench("bench_s2ag.py"),
    Bench("bench_rhythmic.py"),
    Bench("bench_rhythmic_windows.py", quick=("--repeats", "1"), full=(), shared=True),
    Bench("bench_generalize.py"),
    Bench("bench_meaning.py"),
    Bench("bench_live.py"),
    Bench("bench_pipecat.py"),
    Bench("bench_video.py"),
    Bench("bench_plot.py"),
    Bench("bench_say_async.py"),
    Bench(
        "bench_serve_memory.py",
        quick=("--streams", "2", "--length-s", "60", "--time-scale", "4"),
        full=("--streams", "4", "--length-s", "300", "--time-scale", "3"),
    ),
    Bench(
        "bench_learned_heldout.py",
        # one seed; 8 epochs is the least Gesticulator trains before a checkpoint may become its best.pt
        quick=("--take", str(BEAT2_TAKE), "--epochs", "8", "--seeds", "0", "--threads", "1"),
        full=("--take", str(BEAT2_TAKE), "--epochs", "8", "--seeds", "0", "1", "2", "--threads", "1"),
        shared=True,
    ),
    Bench("bench_first_run.py", quick=("--venv", str(FIRST_RUN_VENV)), full=()),
]


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True)
        return out.stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def main(argv: list[str]) -> int:
    bad = [a for a in argv if a.startswith("-") and a != "--full"]
    if bad:
        raise SystemExit(f"unknown option {bad[0]}; usage: python benchmarks/run.py [--full] [NAME ...]")
    full = "--full" in argv
    wanted = [a for a in argv if not a.startswith("-")]
    benches = [b for b in BENCHES if not wanted or any(w in b.script for w in wanted)]
    commit, stamp = _commit(), dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
    rows = []
    failed = 0
    for bench in benches:
        args = bench.full if full and bench.full is not None else bench.quick
        print(f"\n== {' '.join([bench.script, *args])} ==", flush=True)
        if bench.shared and not SHARED_DATA.is_dir():
            print(f"-- {bench.script} skipped: it needs the shared data folder, not found at {SHARED_DATA}")
            continue
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(HERE / bench.script), *args], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        peak_mb = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
        print(proc.stdout.rstrip())
        if proc.returncode != 0:
            failed += 1
            print(f"!! {bench.script} failed (exit {proc.returncode}):\n{proc.stderr.strip()[-2000:]}")
        print(f"-- {bench.script}: {wall:.1f} s wall, peak RSS so far {peak_mb:.0f} MiB")
        for line in proc.stdout.splitlines():
            if line.strip():
                rows.append([stamp, commit, bench.script, f"{wall:.2f}", f"{peak_mb:.0f}", line.strip()])
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
