"""What does the BEAT2 speaker's own motion score on ``bench_generalize.py``'s measures? (a diagnostic)

Issue 13 sets targets for every evaluation clip: stroke-sync z of at least 4 (worst seed 2.5), a wrist-speed
Hellinger distance of at most 0.3 to the speaker's, and a robot that keeps its z within 20 % of the human
motion's. The evaluation clips are 6-40 s long; this script measures the real motion capture of the shared
take with the benchmark's own functions, cut into windows of those lengths, so a generator's figures can be
read beside what real human motion reaches:

1. stroke-sync z of the capture against the take's stressed-vowel onsets (forced alignment), on each half and
   in every window of 8 / 11 / 13 / 16 s (one per second);
2. the Hellinger distance of the held-out half's speech frames, as many at a time as a window of that length
   has, to the calibration half's histogram (:func:`bench_generalize.real_hellinger_floor`), and that half's
   speed and acceleration as ratios to the calibration half's;
3. the capture's wrists relative to its shoulders (the trunk's motion taken out), and the capture played by
   each humanoid (retargeting alone, then retargeting + safety layer at 50 Hz, wrist sites by forward
   kinematics) with its z as a share of the capture's.

Run: ``.venv/bin/python benchmarks/diag_real_floors.py`` (about 30 s).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_generalize as bg

WINDOWS_S = (8.0, 11.0, 13.0, 16.0)
ROBOTS = ("humanoid_xl430", "humanoid_sts3215")


def _wrists(m) -> np.ndarray:
    return m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]  # (T, 2, 3) m


def _window_spans(spans, t0: float, length: float) -> list[tuple[float, float]]:
    return [(max(a - t0, 0.0), min(b - t0, length)) for a, b in spans if b > t0 and a < t0 + length]


def main() -> int:
    from robogest.backends.mujoco_sim import wrist_site_positions
    from robogest.eval.beats import stroke_sync
    from robogest.motion import load_motion
    from robogest.pipeline import DEFAULT_TRAJECTORY_FPS, motion_to_trajectory
    from robogest.retarget import DirectionIK
    from robogest.robot import find_robot

    clips, ref = bg.beat2_clips()
    if not clips:
        print(f"{bg.BEAT2}.* not found: nothing to measure")
        return 0
    mocap = load_motion(bg.BEAT2.with_suffix(".npz"))
    fps = mocap.fps
    halves = []
    for clip, t0 in ((clips[0], 0.0), (clips[1], bg.CUT_S)):
        a, b = round(t0 * fps), round((t0 + clip.speech.duration_s) * fps)
        part = dataclasses.replace(mocap, rotations=mocap.rotations[a:b], root_pos_m=mocap.root_pos_m[a:b])
        halves.append((clip, part))

    print("1. stroke-sync z of the motion capture (the benchmark asks at least 4 of a generator on every clip)")
    for clip, part in halves:
        sp, w, ev = clip.speech, _wrists(part), clip.stressed_vowels_s
        spans = list(sp.silent_spans)
        print(f"  {clip.name}: whole {stroke_sync(w, fps, ev, spans)['z']:.2f}")
        for length in WINDOWS_S:
            zs = []
            for t0 in np.arange(0.0, sp.duration_s - length + 1e-9, 1.0):
                i0, i1 = round(t0 * fps), round((t0 + length) * fps)
                e = ev[(ev >= t0) & (ev < t0 + length)] - t0
                zs.append(stroke_sync(w[i0:i1], fps, e, _window_spans(spans, t0, length))["z"])
            zs = np.asarray(zs)
            print(f"    {length:4.0f} s windows ({zs.size}): mean {np.nanmean(zs):.2f}, max {np.nanmax(zs):.2f}, "
                  f"at least 4: {np.mean(zs >= 4):.0%}")  # fmt: skip

    print("2. the held-out half against the calibration half's speech frames (the benchmark asks H <= 0.3)")
    clip, part = halves[1]
    st = bg.wrist_stats(_wrists(part), fps, clip.speech.silent_spans)
    print(f"  whole half: H {bg.hellinger_to_ref(st['speeds'], ref):.3f}, speed {st['speed'] / ref['speed']:.2f}x, "
          f"acceleration {st['acc'] / ref['acc']:.2f}x")  # fmt: skip
    per_s = st["speeds_by_frame"].shape[0] / clip.speech.duration_s  # speech frames per second of the half
    for length in WINDOWS_S:
        n = round(length * per_s)  # as many speech frames as a window of this length of the half has
        print(f"    {length:4.0f} s of it at a time ({n} speech frames): mean H {bg.real_hellinger_floor(n, ref):.3f}")

    print("3. the motion capture on the robots: z kept (the benchmark asks at least 0.8 of the human z)")
    for clip, part in halves:  # the arms' own share: what a robot with fixed shoulders could keep at best
        p = part.positions()
        sh = p[:, [part.skeleton.index("l_shoulder"), part.skeleton.index("r_shoulder")]]
        rel = stroke_sync(_wrists(part) - sh, fps, clip.stressed_vowels_s, list(clip.speech.silent_spans))["z"]
        print(f"  {clip.name}: the capture's wrists relative to its shoulders {rel:.2f}")
    for name in ROBOTS:
        robot = find_robot(name)
        for clip, part in halves:
            sp, ev = clip.speech, clip.stressed_vowels_s
            spans = list(sp.silent_spans)
            hz = stroke_sync(_wrists(part), fps, ev, spans)["z"]
            ret = DirectionIK(robot).retarget(part.resample(DEFAULT_TRAJECTORY_FPS))
            rz0 = stroke_sync(wrist_site_positions(robot, ret.q_rad), DEFAULT_TRAJECTORY_FPS, ev, spans)["z"]
            traj, _, _ = motion_to_trajectory(part, robot, silent_spans=sp.silent_spans)
            rz = stroke_sync(wrist_site_positions(robot, traj.q_rad), traj.fps, ev, spans)["z"]
            print(f"  {name}, {clip.name}: capture {hz:.2f}, retargeted {rz0:.2f} ({rz0 / hz:.2f}), "
                  f"+ safety {rz:.2f} ({rz / hz:.2f})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
