"""CPU-side preparation of the Rhythmic Gesticulator's training windows, cold and from the block cache.

Usage: ``.venv/bin/python benchmarks/bench_rhythmic_windows.py [--data DIR] [--repeats 3]``. ``DIR`` defaults to
the BEAT2 sample take in ``../shared/data/beat2``. Features come from the feature cache (``hash-test`` text
encoder, computed once before any timing); the timing is :meth:`RhythmicSpec.make_windows` at the paper's
config: cold (beats and time-scaled audio blocks computed, as every launch did before the block cache), then warm
(read from ``--cache-dir``'s ``rhythmic-blocks/``). Prints seconds per minute of speech, on one thread.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "beat2"))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    import torch

    from robogest.data.datasets import load_dataset
    from robogest.data.features import FeatureConfig
    from robogest.data.prep import Normalization
    from robogest.generators.learned.rhythmic import SPEC

    torch.set_num_threads(1)
    tmp = Path(tempfile.mkdtemp(prefix="bench_rhythmic_windows."))
    fcfg = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 16})
    takes = load_dataset(args.data, fcfg, tmp / "features")
    minutes = sum(t.n_frames for t in takes) / fcfg.fps / 60
    norm = Normalization.fit(takes)
    cfg = SPEC.make_config(takes[0].acoustic.shape[1], takes[0].text.shape[1], takes[0].poses.shape[1], {})
    length = cfg.window_blocks * cfg.block

    def once(cache: Path | None, k: int) -> float:
        t0 = time.perf_counter()
        x, _, _ = SPEC.make_windows(takes, norm, cfg, length, 5, store=tmp / f"store{k}", cache_dir=cache)
        x[: min(8, len(x))]  # windows readable
        return time.perf_counter() - t0

    cold = [once(tmp / f"cold{k}", k) for k in range(args.repeats)]  # a fresh cache each time
    warm = [once(tmp / "cold0", 100 + k) for k in range(args.repeats)]  # the first cold run's cache
    for name, ts in (("cold (no block cache)", cold), ("warm (block cache)", warm)):
        med = statistics.median(ts)
        print(f"{name}: {med:.2f} s for {minutes:.2f} min of speech = {med / minutes:.2f} s per minute (median of "
              f"{len(ts)}: {', '.join(f'{t:.2f}' for t in ts)})")  # fmt: skip
    print(f"speed-up {statistics.median(cold) / statistics.median(warm):.1f}x; {len(takes)} take(s) from {args.data}")


if __name__ == "__main__":
    main()
