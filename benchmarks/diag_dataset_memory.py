"""Peak memory of the trainer's data path (load, normalisation statistics, training windows) against dataset size.

A synthetic feature cache (random arrays, MiniLM's 384-d text) is written for ``--takes`` takes of ``--minutes``
each; then, in a fresh process per mode, the trainer's data steps run and the process reports its peak resident
memory (``ru_maxrss``) and the peak of its anonymous (private, non-file) memory, sampled every 2 ms:

* ``mapped``: the cache memory-mapped read-only, as ``load_dataset`` does now;
* ``loaded``: every take's arrays copied into memory first, as the ``.npz`` cache was read before.

File-backed pages of a mapping count in the resident figure while they are read, but they are page cache: shared
between processes (DDP ranks) and given back under memory pressure; the anonymous figure is what the process owns.

    python benchmarks/diag_dataset_memory.py --takes 8 --minutes 10
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

FPS, D_TEXT, WINDOW, STRIDE = 20, 384, 70, 5


def _write_cache(root: Path, n_takes: int, frames: int) -> int:
    from robogest.data import FeatureConfig, discover_takes
    from robogest.data.datasets import cache_entry

    (root / "takes").mkdir(parents=True)
    for i in range(n_takes):  # empty recordings: every take is in the cache
        (root / "takes" / f"take_{i:03d}.wav").touch()
        (root / "takes" / f"take_{i:03d}.npz").touch()
    cfg = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": D_TEXT})
    for i, f in enumerate(discover_takes(root / "takes")):
        e = cache_entry(f, cfg, root / "cache")
        e.mkdir(parents=True)
        rng = np.random.default_rng(i)
        for k, d in (("acoustic", 69), ("text", D_TEXT), ("poses", 51)):
            np.save(e / f"{k}.npy", rng.standard_normal((frames, d), dtype=np.float32))
        (e / "meta.json").write_text(json.dumps({"fps": float(FPS)}))
    return sum(p.stat().st_size for p in (root / "cache").rglob("*.npy"))


def _anon_bytes() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("RssAnon:"))


def _run(root: Path, mode: str) -> dict[str, float]:
    from dataclasses import replace

    from robogest.data import FeatureConfig, Normalization, load_dataset, make_windows, split_takes

    cfg = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": D_TEXT})
    base, anon_base, anon_peak, done = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, _anon_bytes(), [0], []

    def sample() -> None:  # the peak of the anonymous memory, every 2 ms
        while not done:
            anon_peak[0] = max(anon_peak[0], _anon_bytes())
            time.sleep(0.002)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    takes = load_dataset(root / "takes", cfg, root / "cache", warn=print)
    if mode == "loaded":
        takes = [
            replace(t, acoustic=np.array(t.acoustic), text=np.array(t.text), poses=np.array(t.poses)) for t in takes
        ]
    train, _ = split_takes(takes, 0.1, 0)
    norm = Normalization.fit(train)
    x, y, _ = make_windows(train, norm, WINDOW, STRIDE)
    rng = np.random.default_rng(0)
    for _ in range(50):  # a few training batches
        b = rng.integers(0, len(x), 64)
        x[b], y[b]
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    done.append(True)
    sampler.join()
    return {"rss": (peak - base) / 2**20, "anon": (anon_peak[0] - anon_base) / 2**20, "windows": len(x)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--takes", type=int, default=8)
    ap.add_argument("--minutes", type=float, default=10.0, help="length of each take")
    ap.add_argument("--mode", choices=("mapped", "loaded"), help=argparse.SUPPRESS)
    ap.add_argument("--root", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.mode:  # the measuring child
        print(json.dumps(_run(Path(a.root), a.mode)))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        size = _write_cache(Path(tmp), a.takes, round(a.minutes * 60 * FPS))
        print(f"cache: {a.takes} takes x {a.minutes:g} min, {size / 2**20:.0f} MB on disk")
        print("mode     peak RSS MB (with mapped file pages)   peak anonymous MB   windows   (both above the start)")
        for mode in ("mapped", "loaded"):
            out = subprocess.run(
                [sys.executable, __file__, "--mode", mode, "--root", tmp], capture_output=True, text=True, check=True
            )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"{mode:8s} {r['rss']:38.0f} {r['anon']:19.0f} {r['windows']:9d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
