"""Gesticulator inference speed on CPU, as a multiple of real time (not a test; target >= 50x).

Usage: .venv/bin/python benchmarks/bench_gesticulator.py [--seconds 60] [--repeat 5] [--threads 2]
Times the paper-size model (384-d MiniLM text input, random weights: speed does not depend on them) on
pre-computed, normalised input features: the batch path (``predict``, what ``generate`` runs after the speech
front-end) and the streaming path (``infer_stream``, one frame at a time). Speech analysis and text encoding are
timed by bench_speech.py / not included.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from robogest.data import FeatureConfig
from robogest.data.prep import Normalization
from robogest.generators.learned.gesticulator import GesticulatorConfig, GesticulatorGenerator, GesticulatorNet


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0, help="speech length, s")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    cfg = GesticulatorConfig()  # 69 acoustic + 384 text inputs, 51 outputs, paper sizes
    net = GesticulatorNet(cfg)
    norm = Normalization(
        np.zeros(cfg.n_acoustic, np.float32),
        np.ones(cfg.n_acoustic, np.float32),
        np.zeros(cfg.n_pose, np.float32),
        np.ones(cfg.n_pose, np.float32),
    )
    gen = GesticulatorGenerator.from_model(net, FeatureConfig(), norm)
    n = round(args.seconds * 20)
    x = np.random.default_rng(0).standard_normal((n, cfg.n_input)).astype(np.float32)  # (T, 453)
    n_params = sum(p.numel() for p in net.parameters())
    print(
        f"model: {n_params / 1e6:.2f} M parameters; {args.seconds:.0f} s of speech = {n} frames; {args.threads} threads"
    )
    for label, fn in [("predict (batch)", lambda: gen.predict(x)), ("infer_stream", lambda: list(gen.infer_stream(x)))]:
        fn()  # warm-up
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        best, mean = min(times), float(np.mean(times))
        print(
            f"{label:<16} best {args.seconds / best:7.1f}x real time ({1000 * best / n:.3f} ms/frame)"
            f"  mean {args.seconds / mean:7.1f}x"
        )


if __name__ == "__main__":
    main()
