"""Where does speech streamed in real time lose the stroke timing offline has? (issue 16; a diagnostic)

For the two halves of the BEAT2 take and a few seeds, side by side in one run: the strokes each path plans (how
often a stroke's planned speed peak is a hit, i.e. a stressed vowel follows within the stroke-sync window),
the robot's wrist-speed peaks split into those within 0.05 s of a planned stroke peak and the others (count,
hit rate), and, for the stream, how much each plan rewrites the goals of the next 0.3 s beyond the frames
already played (median and 90th percentile of the largest joint change, degrees). Needs ``../shared``.

With ``--rate`` above 1 only the rewrites are printed for the stream: the audio ends before the robot has
played it, no plan follows, and the gestures a plan notes as started (the stream's planned strokes here) miss
the rest.

``.venv/bin/python benchmarks/diag_stream_churn.py [--seeds 0,1,4,8] [--rate 1]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv: list[str]) -> int:
    import bench_live as bl

    from robogest.backends.mujoco_sim import wrist_site_positions
    from robogest.eval.beats import in_speech, stroke_hit_rate, stroke_peaks
    from robogest.live.planner import TrajectoryFeed

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,4,8", help="comma-separated seeds")
    ap.add_argument("--rate", type=float, default=1.0, help="audio delivered this many times real time")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]

    rewrites: list[float] = []  # per splice: largest change of the next 0.3 s of goals, degrees
    splice = TrajectoryFeed.splice

    def recording_splice(feed, start, q_rad, blend_s=0.25, pinned=None):
        old, first_open = feed.q_rad.copy(), feed.first_open
        n = splice(feed, start, q_rad, blend_s, pinned)
        k0 = min(max(start, first_open), old.shape[0])
        k1 = min(k0 + round(0.3 * feed.fps), old.shape[0], feed.q_rad.shape[0])
        if k1 > k0:
            rewrites.append(float(np.degrees(np.abs(feed.q_rad[k0:k1] - old[k0:k1]).max())))
        return n

    TrajectoryFeed.splice = recording_splice
    robot, ik, gen, _ = bl._sync_setup()
    lead = gen.config.stroke_lead_s
    clips = bl._sync_clips((), beat2=True)
    if not clips:
        print("needs ../shared/data/beat2 (absent): nothing to do")
        return 0
    print(f"BEAT2 halves, seeds {seeds}, stream at {args.rate:g}x real time; hit = a stressed vowel follows within "
          "the stroke-sync window")  # fmt: skip
    for name, sp, events in clips:
        keys = ("offline", "streamed") if args.rate == 1.0 else ("offline",)
        pooled = {(k, c): [] for k in keys for c in ("planned", "stroke", "other")}  # times, pooled over seeds
        rewrites.clear()
        for seed in seeds:
            planned_off = np.array([e.t_s - lead for _, _, e in gen.strokes(sp, seed)])
            planners: list = []
            feed = bl._streamed(robot, gen, ik, sp, seed, args.rate, planners=planners)
            arms = [e for e in planners[0].live.started.values() if gen.repertoire.units[e.unit].channel == "arms"]
            runs = {"offline": (bl._offline(robot, gen, sp, seed), planned_off)}
            if args.rate == 1.0:
                runs["streamed"] = (bl._played(robot, feed), np.array([e.t_s - lead for e in arms]))
            for key, (goals, planned) in runs.items():
                peaks = stroke_peaks(wrist_site_positions(robot, goals), 100.0)
                peaks = peaks[in_speech(peaks, sp.silent_spans)]
                on = np.array([planned.size > 0 and np.abs(planned - p).min() < 0.05 for p in peaks], bool)
                pooled[key, "planned"].append(planned)
                pooled[key, "stroke"].append(peaks[on])
                pooled[key, "other"].append(peaks[~on])
        print(f"\n{name}")
        print(f"  {'':<10}{'planned strokes':>22}{'peaks on a stroke':>22}{'other peaks':>22}")
        for key in keys:
            cells = []
            for c in ("planned", "stroke", "other"):
                t = np.concatenate(pooled[key, c])
                cells.append(f"{t.size:>5} hit {stroke_hit_rate(t, events):.2f}")
            print(f"  {key:<10}" + "".join(f"{c:>22}" for c in cells))
        rw = np.array(rewrites)
        print(f"  each plan rewrites the next 0.3 s of goals by {np.median(rw):.2f} deg (median), "
              f"{np.percentile(rw, 90):.1f} deg (90th percentile), {rw.size} plans")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
