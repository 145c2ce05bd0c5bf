"""S2AG inference speed on CPU, as a multiple of real time (not a test; target >= 20x).

Usage: .venv/bin/python benchmarks/bench_s2ag.py [--seconds 60] [--repeat 5] [--threads 2]
Times the paper-size generator (Table 1 sizes, 2-layer Bi-GRUs, 384-d MiniLM text input, 4 speakers, random
weights: speed does not depend on them) on pre-computed, normalised MFCC and text features: the chained-window
``predict`` and the direction -> canonical rotation conversion, i.e. what ``generate`` runs after the speech
front-end. Speech analysis and text encoding are timed by bench_speech.py / not included.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from robogest.data import FeatureConfig
from robogest.generators.learned.s2ag import S2AGConfig, S2AGGenerator, S2AGNet, directions_to_motion


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0, help="speech length, s")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    cfg = S2AGConfig(
        n_text=384, speakers=("0", "1", "2", "3"), mfcc_mean=(0.0,) * 37, mfcc_std=(1.0,) * 37,
        dir_mean=tuple(np.tile([0.0, 1.0, 0.0], 9) * 0.5),
    )  # fmt: skip
    gen = S2AGGenerator.from_model(S2AGNet(cfg), FeatureConfig(), speaker="sample")
    n = round(args.seconds * 20)
    rng = np.random.default_rng(0)
    mfcc = rng.standard_normal((n, 37)).astype(np.float32)
    text = rng.standard_normal((n, 384)).astype(np.float32)
    z = gen.style_vector("sample", 0)
    gen.predict(mfcc[:200], text[:200], z)  # warm-up
    t_model, t_conv = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        dirs = gen.predict(mfcc, text, z)
        t1 = time.perf_counter()
        directions_to_motion(dirs, 20.0)
        t2 = time.perf_counter()
        t_model.append(t1 - t0)
        t_conv.append(t2 - t1)
    m, c = min(t_model), min(t_conv)
    print(f"s2ag, {args.seconds:.0f} s of speech, {args.threads} thread(s), best of {args.repeat}:")
    print(f"  model (chained {cfg.seq_len}-frame windows): {m * 1e3:8.1f} ms  {args.seconds / m:8.1f}x real time")
    print(f"  directions -> canonical rotations:       {c * 1e3:8.1f} ms  {args.seconds / c:8.1f}x real time")
    print(
        f"  total:                                   {(m + c) * 1e3:8.1f} ms  {args.seconds / (m + c):8.1f}x real time"
    )


if __name__ == "__main__":
    main()
