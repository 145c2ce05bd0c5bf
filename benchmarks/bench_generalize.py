"""Does the default generator's timing generalize to speech it was not tuned on? (a benchmark, not a test)

Protocol (issue 13 §2). The generator may be calibrated only on the **first half** (0-32 s) of the shared
BEAT2 take (speaker "scott"); everything else is held out: the take's second half, eSpeak NG paragraphs of
different lengths, punctuation and speaking rates, and other eSpeak voices (the only other speech this
offline machine has). For every clip and each of 10 seeds it measures, on the generated human motion:

- stroke-sync z (:func:`robogest.eval.beats.stroke_sync`: wrist-speed peaks during speech that precede a
  stressed-vowel onset by 0 to 0.2 s, chance from circular shifts). The events are stressed-vowel onsets,
  the kind the measure is validated with: the take's forced alignment (TextGrid phones, ARPAbet stress 1/2)
  for the BEAT2 halves, eSpeak NG's own stressed syllables (:func:`robogest.speech.synthesize_with_stress`)
  for the synthesized clips; no generator sees either;
- wrist speed and acceleration during speech, as ratios to the speaker's in the calibration half (the
  reference is calibration data too, so no held-out motion is ever looked at); the motion is generated at
  the mocap's 30 fps so finite differences are comparable;
- Hellinger distance between the wrist-speed histograms (1 cm/s bins, speech frames) of the two;
- rest: fraction of pauses of 1 s or more in which the wrists hold still (< 1 cm/s) from 0.6 s after the
  pause starts to 0.45 s before it ends;
- ceiling_z: the z of strokes on every acoustic beat the generator sees, each ``stroke_lead_s`` before
  its beat as the generator places them (no seeds): what this metric allows a generator that strokes on
  those beats (short clips with dense onsets cap it well below 4);
- on the robot (humanoid_xl430: retarget + safety layer at 50 Hz, MuJoCo wrist sites of the command
  trajectory): stroke-sync z and its ratio to the human motion's z of the same seed.

The table gives mean and worst seed per clip and metric (worst: lowest z / rest, largest Hellinger, ratio
farthest from 1), the calibration clip apart from the held-out ones. Run:
``.venv/bin/python benchmarks/bench_generalize.py [--seeds N] [--calibration-only] [--no-robot] [--only TEXT]``.
Calibrating a ``RhythmConfig`` field: ``--calibration-only --grid NAME=V1,V2,...`` prints the table for each
value and the value with the highest mean stroke-sync z on the calibration half (use it only with
``--calibration-only``: choosing on held-out clips would tune to them).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

BEAT2 = Path(__file__).resolve().parents[1].parent / "shared/data/beat2/2_scott_0_1_1"
CUT_S = 32.0
MOCAP_FPS = 30.0
ROBOT = "humanoid_xl430"

#: (name, voice, words per minute, text): lengths 6-40 s, questions, lists, exclamations, ellipsis pauses.
TTS: list[tuple[str, str, int, str]] = [
    ("tts greeting 175wpm", "en-us", 175, "Hello there! It is really nice to meet you. My name is Robo, and I "
     "will be your guide today. Shall we get started?"),
    ("tts questions 150wpm", "en-us", 150, "Have you ever wondered why people move their hands when they "
     "talk? Is it for the listener, or for the speaker? ... Nobody knows for sure. What do you think? Maybe "
     "it is a little bit of both."),
    ("tts list 200wpm", "en-us", 200, "There are three things you need: first, a clear goal; second, a good "
     "plan; and third, the patience to follow it, day after day, even when it gets hard. That is all, "
     "really, nothing more and nothing less."),
    ("tts story 160wpm", "en-us", 160, "Last summer my family and I drove all the way to the coast. The "
     "road was long and the car was old, but we sang the whole way there. ... When we finally arrived, the "
     "sea was huge and grey and wild. My little brother ran straight into the water, shoes and all. We "
     "laughed so hard that we could not breathe. ... I think about that day a lot. It was not perfect, but "
     "it was ours, and I would not change a thing about it."),
    ("tts slow 120wpm", "en-us", 120, "No! Absolutely not. I will never agree to that. ... You have to "
     "understand: this is important to me, and to everyone here."),
    ("tts fast 230wpm", "en-us", 230, "So the numbers are in: revenue grew by twelve percent, costs went "
     "down by four, and our team doubled in size, which means we can finally build the things we have "
     "been talking about for years, starting right now."),
    ("espeak en-gb-scotland 150wpm", "en-gb-scotland", 150, "Well, I am not sure about that. The weather "
     "up here changes every five minutes, so you always carry a coat. ... But when the sun comes out, there "
     "is no better place in the whole world."),
    ("espeak en-029 170wpm", "en-029", 170, "Come on, come with me, I want to show you something. Right "
     "over there, past the big tree, you can see the whole bay. Is that not beautiful?"),
    ("espeak de 150wpm", "de", 150, "Guten Morgen! Heute möchte ich Ihnen zeigen, wie ein kleiner Roboter "
     "beim Sprechen die Arme bewegt. ... Das ist gar nicht so einfach, wie es aussieht."),
]  # fmt: skip


@dataclass
class Clip:
    name: str
    speech: object  # robogest.speech.types.Speech
    stressed_vowels_s: np.ndarray  # the stroke-sync reference events, s; never given to a generator
    calibration: bool = False


def _cut(speech, t0: float, t1: float):
    """The part ``[t0, t1)`` s of a Speech, re-analysed (words shifted, those crossing the cut dropped)."""
    from robogest.speech.core import analyze
    from robogest.speech.types import Word

    a = speech.audio[round(t0 * speech.sr) : round(t1 * speech.sr)]
    words = [
        Word(w.text, w.start_s - t0, w.end_s - t0, w.syllables)
        for w in speech.words
        if t0 <= w.start_s and w.end_s <= t1
    ]
    return replace(analyze(a, speech.sr, words, source=f"{speech.source}[{t0:g}-{t1:g}s]"), audio_path=None)


def beat2_clips() -> tuple[list[Clip], dict]:
    """The two halves of the shared take and the speaker's reference statistics (calibration half only)."""
    from robogest.motion import load_motion
    from robogest.speech import load_speech
    from robogest.speech.transcript import read_stressed_vowels

    if not BEAT2.with_suffix(".wav").is_file():
        return [], {}
    full = load_speech(BEAT2.with_suffix(".wav"), BEAT2.with_suffix(".TextGrid"))
    stressed = read_stressed_vowels(BEAT2.with_suffix(".TextGrid"))
    mocap = load_motion(BEAT2.with_suffix(".npz"))
    end = mocap.n_frames / mocap.fps
    calib = _cut(full, 0.0, CUT_S)
    held = _cut(full, CUT_S, end)
    w = mocap.positions()[:, [mocap.skeleton.index("l_wrist"), mocap.skeleton.index("r_wrist")]]  # (T, 2, 3) m
    cut = round(CUT_S * mocap.fps)
    ref = wrist_stats(w[:cut], mocap.fps, calib.silent_spans)
    # The speaker's own held-out speech frames, in time order: what a real-vs-real Hellinger is drawn from.
    ref["held_speeds"] = wrist_stats(w[cut:], mocap.fps, held.silent_spans)["speeds_by_frame"]

    def cut_events(t0: float, t1: float) -> np.ndarray:
        return stressed[(stressed >= t0) & (stressed < t1)] - t0

    clips = [
        Clip("BEAT2 scott 0-32 s", calib, cut_events(0.0, CUT_S), calibration=True),
        Clip(f"BEAT2 scott 32-{end:.0f} s", held, cut_events(CUT_S, end)),
    ]
    return clips, ref


def wrist_stats(w: np.ndarray, fps: float, silent_spans) -> dict:
    """Wrist speeds (cm/s) and acceleration magnitudes (cm/s²) during speech, both wrists pooled."""
    from robogest.eval.kinematics import spans_to_mask

    speech = ~spans_to_mask(list(silent_spans), w.shape[0], fps)
    v = np.diff(w, axis=0) * fps * 100  # (T-1, W, 3) cm/s
    a = np.diff(w, n=2, axis=0) * fps**2 * 100  # (T-2, W, 3) cm/s²
    sv = np.linalg.norm(v, axis=-1)[speech[1:] & speech[:-1]]  # (N, W)
    sa = np.linalg.norm(a, axis=-1)[speech[2:] & speech[1:-1] & speech[:-2]]
    return {"speeds": sv.ravel(), "speeds_by_frame": sv, "speed": float(sv.mean()), "acc": float(sa.mean())}


def hellinger_to_ref(speeds: np.ndarray, ref: dict) -> float:
    """Hellinger distance between the histograms (1 cm/s bins) of ``speeds`` (cm/s) and the speaker's."""
    from robogest.eval.kinematics import hellinger_distance, speed_histogram

    top = max(speeds.max(), ref["speeds"].max())
    return hellinger_distance(speed_histogram(speeds, 1.0, top)[0], speed_histogram(ref["speeds"], 1.0, top)[0])


def real_hellinger_floor(n_frames: int, ref: dict, step: int = 30) -> float:
    """What the speaker's own motion scores: the mean Hellinger distance to his calibration-half histogram of
    every run of ``n_frames`` consecutive speech frames (both wrists) of his held-out half, one run every
    ``step`` frames. A histogram of few frames is noisy and the distance grows as frames get fewer, so a clip's
    distance means something only beside this floor for its length (NaN when the held-out half is shorter)."""
    held = ref["held_speeds"]  # (N, 2) cm/s
    if n_frames > held.shape[0]:
        return float("nan")
    starts = range(0, held.shape[0] - n_frames + 1, step)
    return float(np.mean([hellinger_to_ref(held[i : i + n_frames].ravel(), ref) for i in starts]))


def rest_held(w: np.ndarray, fps: float, silent_spans, duration_s: float) -> float:
    """Fraction of pauses >= 1 s in which the wrists stay under 1 cm/s (NaN when there is no such pause)."""
    ok = []
    speed = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) * fps * 100  # (T-1,) cm/s
    tv = (np.arange(speed.size) + 0.5) / fps
    for a, b in silent_spans:
        if b - a < 1.0:
            continue
        t0 = a if a <= 1e-6 else a + 0.6
        t1 = b if b >= duration_s - 1e-6 else b - 0.45
        inside = (tv >= t0) & (tv <= t1)
        if inside.any():
            ok.append(bool(speed[inside].max() < 1.0))
    return float(np.mean(ok)) if ok else float("nan")


def tts_clips() -> list[Clip]:
    from robogest.speech import synthesize_with_stress

    return [
        Clip(name, *synthesize_with_stress(text, voice=voice, words_per_minute=wpm)) for name, voice, wpm, text in TTS
    ]


def measure(clip: Clip, ref: dict, seeds: range, robot=None, generator_options: dict | None = None) -> dict:
    """Per-seed metrics of one clip: lists under each metric name."""
    from robogest.eval.beats import chance_corrected, stroke_hit_rate, stroke_sync, stroke_sync_events
    from robogest.generators import make_generator

    sp = clip.speech
    gen = make_generator("rhythm", fps=MOCAP_FPS, **(generator_options or {}))
    onsets, kind = stroke_sync_events(sp.audio, sp.sr, stressed_vowels_s=clip.stressed_vowels_s)
    assert kind == "stressed_vowels", kind
    spans = list(sp.silent_spans)
    out: dict[str, list[float]] = {k: [] for k in ("z", "speed", "acc", "hellinger", "rest", "robot_z", "robot/human")}
    # The most this generator could score here: one stroke (led as it leads them) on every beat it can see.
    beats = gen.beats(sp).t_s - gen.config.stroke_lead_s
    ceiling = chance_corrected(lambda m, a: stroke_hit_rate(m, a, spans), beats, onsets, sp.duration_s)["z"]
    out["ceiling_z"] = [ceiling]
    for seed in seeds:
        m = gen.generate(sp, seed=seed)
        w = m.positions()[:, [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]]
        z = stroke_sync(w, m.fps, onsets, spans)["z"]
        st = wrist_stats(w, m.fps, spans)
        h = hellinger_to_ref(st["speeds"], ref)
        out["z"].append(z)
        out["speed"].append(st["speed"] / ref["speed"])
        out["acc"].append(st["acc"] / ref["acc"])
        out["hellinger"].append(h)
        if seed == seeds[0]:  # the same number of speech frames for every seed
            out["real_H"] = [real_hellinger_floor(st["speeds_by_frame"].shape[0], ref)]
        out["rest"].append(rest_held(w, m.fps, spans, sp.duration_s))
        if robot is not None:
            from robogest.backends.mujoco_sim import wrist_site_positions
            from robogest.pipeline import motion_to_trajectory

            traj, _, _ = motion_to_trajectory(m, robot, silent_spans=sp.silent_spans)
            rz = stroke_sync(wrist_site_positions(robot, traj.q_rad), traj.fps, onsets, spans)["z"]
            out["robot_z"].append(rz)
            out["robot/human"].append(rz / z if z else float("nan"))
    return out


#: How "worst" is picked per metric.
WORST = {
    "ceiling_z": np.nanmin,
    "z": np.nanmin,
    "rest": np.nanmin,
    "robot_z": np.nanmin,
    "hellinger": np.nanmax,
    "real_H": np.nanmax,
    "speed": lambda x: x[np.nanargmax(np.abs(np.log(x)))],
    "acc": lambda x: x[np.nanargmax(np.abs(np.log(x)))],
    "robot/human": lambda x: x[np.nanargmax(np.abs(np.asarray(x) - 1))],
}


def table(results: dict[str, dict], calibration: set[str]) -> list[str]:
    """Clip x metric rows, ``mean (worst)``; the calibration clip first, set apart."""
    keys = [k for k in WORST if any(len(r[k]) for r in results.values())]
    width = max(len(n) for n in results) + 2
    head = "clip".ljust(width) + "".join(k.rjust(16) for k in keys)
    lines = [head]
    for group, title in ((True, "calibration (tuned on)"), (False, "held out")):
        names = [n for n in results if (n in calibration) == group]
        if not names:
            continue
        lines.append(f"-- {title}")
        for n in names:
            cells = []
            for k in keys:
                x = np.asarray(results[n][k], dtype=float)
                if x.size == 0 or np.all(np.isnan(x)):
                    cells.append("n/a".rjust(16))
                    continue
                cells.append(f"{np.nanmean(x):.2f} ({float(WORST[k](x)):.2f})".rjust(16))
            lines.append(n.ljust(width) + "".join(cells))
    return lines


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--calibration-only", action="store_true", help="only the calibration half (for tuning)")
    ap.add_argument("--no-robot", action="store_true", help="skip the robot (retarget + safety + MuJoCo sites)")
    ap.add_argument("--only", metavar="TEXT", help="only the clips whose name contains TEXT (a smoke run)")
    ap.add_argument("--grid", metavar="NAME=V1,V2,...", help="run once per value of a RhythmConfig field")
    args = ap.parse_args(argv)
    grid: list[dict] = [{}]
    if args.grid:
        name, _, values = args.grid.partition("=")
        grid = [{name: float(v)} for v in values.split(",") if v]
    t0 = time.perf_counter()
    clips, ref = beat2_clips()
    if not clips:
        print(f"{BEAT2}.* not found: the protocol needs the shared BEAT2 take for calibration and reference")
        return 0
    if args.calibration_only:
        clips = clips[:1]
    else:
        clips += tts_clips()
    if args.only:
        clips = [c for c in clips if args.only in c.name]
    robot = None
    if not args.no_robot:
        from robogest.robot import find_robot

        robot = find_robot(ROBOT)
    print(f"generator 'rhythm', {args.seeds} seeds per clip; mean (worst seed); speed/acc as ratios to the speaker's")
    print(f"reference speaker: calibration half, speech frames: {ref['speed']:.1f} cm/s, {ref['acc']:.0f} cm/s²")
    calib_z = []
    for opts in grid:
        results = {c.name: measure(c, ref, range(args.seeds), robot, opts) for c in clips}
        if opts:
            print(f"== {opts}")
        print("\n".join(table(results, {c.name for c in clips if c.calibration})))
        calib_z += [(float(np.mean(results[c.name]["z"])), str(opts)) for c in clips if c.calibration]
    if len(grid) > 1 and calib_z:
        best = max(calib_z)
        print(f"grid: highest mean z on the calibration half {best[0]:.2f} at {best[1]}")
    print(f"wall {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
