"""Benchmark ``--plot`` (not a test): CPU and wall time to draw and write the PNG for a short clip and for 64 s
of speech with 199 words (the test fixtures of tests/viz/test_plot.py), and how many word labels fit.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_plot.py [--seconds 64] [--words 199]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from robogest.motion.human_motion import HumanMotion
from robogest.viz.plot import motion_figure, plot_motion
from tests.viz.test_plot import make_speech, make_trajectory


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=64.0)
    p.add_argument("--words", type=int, default=199)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for duration_s, n_words in ((2.5, 6), (args.seconds, args.words)):
            speech, traj = make_speech(duration_s, n_words), make_trajectory(duration_s)
            motion = HumanMotion.rest(round(duration_s * 20), 20.0)
            cpu, wall = time.process_time(), time.perf_counter()
            plot_motion(Path(tmp) / "p.png", motion, speech, traj)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            labels = sum(len(ax.texts) for ax in motion_figure(motion, speech, traj).axes)
            print(f"{duration_s:5.1f} s, {n_words:3d} words: {cpu:5.2f} s CPU, {wall:5.2f} s wall, {labels} labelled")


if __name__ == "__main__":
    main()
