"""Does the safety layer move the strokes in time? The robot's wrist speed against the IK targets' it follows.

For every clip of ``bench_generalize`` (the BEAT2 halves and the synthesized ones) and a few seeds of the default
generator: the lag (ms) at which the wrist-site speed of the safe trajectory best correlates with that of the
raw IK joint targets, that correlation, and the stroke-sync z of both, with the causal safety path
(``SafetyConfig(preview=False)``) and with the zero-lag preview fit (the default), side by side in one run.

``.venv/bin/python benchmarks/diag_safety_lag.py [--seeds N]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def speed(w: np.ndarray, fps: float) -> np.ndarray:
    """Faster wrist's speed ``(T-1,)`` m/s of wrist positions ``w (T, 2, 3)``."""
    return np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) * fps


def lag_ms(a: np.ndarray, b: np.ndarray, fps: float, max_lag: int = 10) -> tuple[float, float]:
    """How far ``b`` trails ``a`` (cross-correlation peak, ms) and their correlation at lag 0."""
    n = min(a.size, b.size)
    a, b = a[:n] - a[:n].mean(), b[:n] - b[:n].mean()
    lags = range(-max_lag, max_lag + 1)
    c = [np.dot(a[max(0, -k) : n - max(0, k)], b[max(0, k) : n - max(0, -k)]) for k in lags]
    return list(lags)[int(np.argmax(c))] * 1000.0 / fps, float(np.corrcoef(a, b)[0, 1])


def main(argv: list[str]) -> int:
    import bench_generalize as bg

    from robogest.backends.mujoco_sim import wrist_site_positions
    from robogest.eval.beats import stroke_sync, stroke_sync_events
    from robogest.generators import make_generator
    from robogest.pipeline import motion_to_trajectory
    from robogest.robot import find_robot
    from robogest.safety import SafetyConfig

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    robot = find_robot(bg.ROBOT)
    fps = 50.0
    clips = bg.beat2_clips()[0] + bg.tts_clips()
    print(f"{robot.name}, {args.seeds} seeds per clip; mean over seeds")
    print(
        f"{'clip':<30} {'IK z':>6} | {'causal: lag ms':>14} {'corr':>5} {'z':>6} "
        f"| {'preview: lag ms':>15} {'corr':>5} {'z':>6}"
    )
    for clip in clips:
        sp = clip.speech
        onsets, _ = stroke_sync_events(sp.audio, sp.sr, stressed_vowels_s=clip.stressed_vowels_s)
        spans = list(sp.silent_spans)
        gen = make_generator("rhythm", fps=fps)
        rows = []
        for seed in range(args.seeds):
            m = gen.generate(sp, seed=seed)
            row = []
            for preview in (False, True):
                traj, ret, _ = motion_to_trajectory(m, robot, silent_spans=sp.silent_spans,
                                                    safety=SafetyConfig(preview=preview))  # fmt: skip
                w_ik, w_safe = wrist_site_positions(robot, ret.q_rad), wrist_site_positions(robot, traj.q_rad)
                if not row:
                    row.append(stroke_sync(w_ik, fps, onsets, spans)["z"])
                row += [
                    *lag_ms(speed(w_ik, fps), speed(w_safe, fps), fps),
                    stroke_sync(w_safe, fps, onsets, spans)["z"],
                ]
            rows.append(row)
        r = np.mean(rows, axis=0)
        print(
            f"{clip.name[:30]:<30} {r[0]:6.2f} | {r[1]:14.0f} {r[2]:5.2f} {r[3]:6.2f} "
            f"| {r[4]:15.0f} {r[5]:5.2f} {r[6]:6.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
