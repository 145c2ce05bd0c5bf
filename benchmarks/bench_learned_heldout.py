"""Held-out evidence for the learned generators on one real take (issue 15 §5).

Usage::

    .venv/bin/python benchmarks/bench_learned_heldout.py --take ../shared/data/beat2/2_scott_0_1_1 \
        [--models gesticulator s2ag rhythmic] [--epochs 8] [--seeds 0 1 2] [--out runs/heldout] [--threads 2]

Each model trains on the take's first 70 % (the trainer splits a one-take dataset in time: ``--val-fraction 0.3``
holds out the last 30 % as its validation take, so the logged held-out loss is on unseen speech) and then
generates the last 30 % free-running from its audio and transcript alone. Two baselines get the same evaluation:
the mean training pose held still, and a replay of a random stretch of the training motion of the same length
(a new stretch per seed). Every seed trains every model afresh; the table gives the mean over seeds and, in
brackets, the worst seed.

Printed per model and baseline:

- the held-out loss of ``best.pt`` (each model's own validation objective, not comparable across models);
- acceleration and jerk ratios to the real held-out motion on the model's paper joint set
  (:data:`robogest.eval.kinematics.PAPER_JOINT_SETS`, root translation removed): Gesticulator on ``gesticulator``
  (its §5.1 upper body), S2AG on ``s2ag`` (the TED joints of its §5.2), the Rhythmic Gesticulator on
  ``gesticulator`` (its paper reports no acceleration or jerk; on motion capture, which this take is, it models
  the Trinity upper body with a fixed root, which that set is). Baselines get a row per set;
- MAJE (mm, all joints; Rhythmic Gesticulator Table 1);
- stroke sync (:func:`robogest.eval.beats.stroke_sync`: wrist-speed peaks during speech followed within 0.2 s
  by a stressed-vowel onset of the take's TextGrid, the validated events; z over circular time shifts);
- ``beats both``: in how many seeds the model beats each baseline on every criterion: acceleration and jerk ratios
  closer to 1 (in ``|log ratio|``) on its set, lower MAJE, higher stroke-sync z (no strokes = no sync); the
  criteria it failed are counted in brackets.

One take of about a minute cannot show that a model generalises across speakers or content; it can show whether
training on real speech runs end to end and whether the held-out motion is better than trivial baselines.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
from pathlib import Path

HOLDOUT = 0.3
#: Each model's paper joint set for acceleration and jerk (see the module docstring for the Rhythmic Gesticulator).
MODEL_SET = {"gesticulator": "gesticulator", "s2ag": "s2ag", "rhythmic": "gesticulator"}
SET_LABEL = {"gesticulator": "Gesticulator (13)", "s2ag": "S2AG (10)"}
MODEL_LABEL = {"gesticulator": "Gesticulator", "s2ag": "S2AG", "rhythmic": "Rhythmic Gesticulator"}
CRITERIA = ("accel", "jerk", "MAJE", "sync")


def _held_out_speech(wav: Path, transcript: Path, cut_s: float):
    """The last part of the take from ``cut_s`` on, analysed as the generators see speech at run time."""
    from robogest.speech import analyze
    from robogest.speech.audio import read_audio
    from robogest.speech.config import SpeechConfig
    from robogest.speech.transcript import read_transcript
    from robogest.speech.types import Word

    audio, sr = read_audio(wav, float("inf"))
    words = [
        Word(w.text, w.start_s - cut_s, w.end_s - cut_s, w.syllables)
        for w in read_transcript(transcript).words
        if w.start_s >= cut_s
    ]
    return analyze(audio[round(cut_s * sr) :], sr, words, SpeechConfig(), source=f"{wav}[{cut_s:.1f}s:]")


def _evaluate(motion, gt, onsets, spans) -> dict:
    """Paper-set acceleration/jerk ratios, MAJE and stroke sync of ``motion`` against the real ``gt``."""
    from robogest.eval.beats import stroke_sync
    from robogest.eval.kinematics import maje_mad, paper_statistics
    from robogest.eval.report import wrist_indices

    n = min(motion.n_frames, gt.n_frames)
    names = list(gt.skeleton.names)
    pred, real = motion.positions()[:n], gt.positions()[:n]  # (n, J, 3) metres
    sets = paper_statistics(pred, gt.fps, names, real)
    sync = stroke_sync(pred[:, wrist_indices(names)], gt.fps, onsets, spans)
    row = {"maje_mm": maje_mad(pred, real, gt.fps)["maje_mm"], "sync_z": sync["z"], "sync_hit": sync["hit"]}
    for s, e in sets.items():
        row[f"{s}_accel"] = e["ratio_to_gt"]["acceleration_ratio"]
        row[f"{s}_jerk"] = e["ratio_to_gt"]["jerk_ratio"]
    return row


def _off(ratio: float) -> float:
    """How far a ratio is from 1, symmetric for half and double; a still motion (ratio 0) is infinitely far."""
    return abs(math.log(ratio)) if ratio > 0 else math.inf


def _z(row: dict) -> float:
    """Stroke-sync z; a motion without strokes (the still mean pose) has no sync at all."""
    z = row["sync_z"]
    return z if z == z else -math.inf


def _failed(row: dict, base: dict, joint_set: str) -> set[str]:
    """The criteria on which ``row`` does not beat the baseline ``base`` (see the module docstring)."""
    bad = set()
    for c in ("accel", "jerk"):
        if not _off(row[f"{joint_set}_{c}"]) < _off(base[f"{joint_set}_{c}"]):
            bad.add(c)
    if not row["maje_mm"] < base["maje_mm"]:
        bad.add("MAJE")
    if not _z(row) > _z(base):
        bad.add("sync")
    return bad


def _agg(values: list[float], worst, fmt: str) -> str:
    """``mean (worst)`` over seeds; just the value where every seed gives the same."""
    vals = [v for v in values if v == v]
    if not vals:
        return "n/a"
    mean = sum(vals) / len(vals)
    return fmt.format(mean) if min(vals) == max(vals) else f"{fmt.format(mean)} ({fmt.format(worst(vals))})"


def table(runs: list[dict], models: list[str]) -> list[str]:
    """Markdown rows of the held-out table from per-seed results ``runs`` (each: row name -> metrics)."""
    k = len(runs)
    far = lambda vals: max(vals, key=_off)  # noqa: E731 - the worst ratio is the one farthest from 1
    lines = [
        "| | joint set | held-out loss | accel ratio | jerk ratio | MAJE mm | stroke sync z | beats both baselines |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def line(name: str, key: str, joint_set: str | None, loss: str, both: str) -> str:
        """One row; ``joint_set`` None for motions whose ratios are the same on every set (real: 1, still: 0)."""
        label = "any" if joint_set is None else SET_LABEL[joint_set]
        joint_set = joint_set or next(iter(SET_LABEL))
        rs = [r[key] for r in runs]
        acc = _agg([r[f"{joint_set}_accel"] for r in rs], far, "{:.2f}")
        jerk = _agg([r[f"{joint_set}_jerk"] for r in rs], far, "{:.2f}")
        maje = _agg([r["maje_mm"] for r in rs], max, "{:.1f}")
        z = _agg([r["sync_z"] for r in rs], min, "{:.2f}")
        z = "n/a (no strokes)" if z == "n/a" else z
        return f"| {name} | {label} | {loss} | {acc} | {jerk} | {maje} | {z} | {both} |"

    lines.append(line("real held-out motion", "real", None, "-", "-"))
    lines.append(line("baseline: mean training pose", "mean pose", None, "-", "-"))
    for s in SET_LABEL:
        lines.append(line("baseline: replay of training motion", "replay", s, "-", "-"))
    for m in models:
        s = MODEL_SET[m]
        losses = _agg([r[m]["held_out_loss"] for r in runs], max, "{:.3f}")
        fails = [_failed(r[m], r["mean pose"], s) | _failed(r[m], r["replay"], s) for r in runs]
        wins = sum(not f for f in fails)
        why = ", ".join(f"{c} {sum(c in f for f in fails)}/{k}" for c in CRITERIA if any(c in f for f in fails))
        lines.append(line(MODEL_LABEL[m], m, s, losses, f"{wins}/{k}" + (f" (fails {why})" if why else "")))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--take", required=True, help="path without suffix: TAKE.wav, TAKE.npz|.bvh, TAKE.TextGrid")
    ap.add_argument("--models", nargs="+", default=["gesticulator", "s2ag", "rhythmic"], choices=list(MODEL_SET))
    ap.add_argument("--epochs", type=int, default=8)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--text-encoder", default="minilm")
    args = ap.parse_args()

    import numpy as np
    import torch

    from robogest.data.features import expmap_to_motion, motion_to_expmap
    from robogest.generators import make_generator
    from robogest.generators.learned import train_model
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig
    from robogest.motion import load_motion
    from robogest.speech.transcript import read_stressed_vowels

    torch.set_num_threads(args.threads)
    take = Path(args.take)
    wav, tg = take.with_suffix(".wav"), take.with_suffix(".TextGrid")
    mfile = next(p for p in (take.with_suffix(".npz"), take.with_suffix(".bvh")) if p.is_file())
    out = Path(args.out or tempfile.mkdtemp(prefix="heldout-"))
    data = out / "data"
    data.mkdir(parents=True, exist_ok=True)
    for src in (wav, mfile, tg):
        shutil.copy(src, data / src.name)

    gt_all = load_motion(mfile).resample(20.0)
    cut = round(gt_all.n_frames * (1 - HOLDOUT))
    cut_s = cut / gt_all.fps
    poses = motion_to_expmap(gt_all)  # (T, J * 3)
    gt = expmap_to_motion(poses[cut:], gt_all.fps)  # canonical root, as generated motion has
    speech = _held_out_speech(wav, tg, cut_s)
    stressed = read_stressed_vowels(tg)
    if stressed is None:
        raise SystemExit(f"{tg}: no stress-marked phones tier; stroke sync is validated only with one")
    onsets = stressed[stressed >= cut_s] - cut_s  # (K,) seconds into the held-out part; no generator sees them
    spans = [(float(a), float(b)) for a, b in speech.silent_spans]
    n = min(gt.n_frames, speech.n_frames)

    runs = []
    for seed in args.seeds:
        rows = {"real": _evaluate(gt, gt, onsets, spans)}
        rows["mean pose"] = _evaluate(
            expmap_to_motion(np.repeat(poses[:cut].mean(0, keepdims=True), n, 0), gt.fps), gt, onsets, spans
        )
        start = np.random.default_rng(seed).integers(0, max(1, cut - n))
        rows["replay"] = _evaluate(expmap_to_motion(poses[start : start + n], gt.fps), gt, onsets, spans)
        for model in args.models:
            run_dir = out / f"seed{seed}" / model
            cfg = TrainConfig(
                model=model, data=str(data), out=str(run_dir), epochs=args.epochs, val_fraction=HOLDOUT,
                device="cpu", seed=seed, text_encoder=args.text_encoder, cache_dir=str(out / "cache"),
                window_stride=2,
            )  # fmt: skip
            best = train_model(cfg, log=lambda s, m=model, sd=seed: print(f"[{m} seed {sd}] {s}", flush=True))
            motion = make_generator(model, checkpoint=str(best)).generate(speech, seed=seed)
            rows[model] = _evaluate(motion, gt, onsets, spans)
            rows[model]["held_out_loss"] = float(load_checkpoint(best)["train_state"]["best_val"])
        runs.append(rows)
        (out / "heldout.json").write_text(json.dumps({"seeds": args.seeds[: len(runs)], "runs": runs}, indent=1))

    print(
        f"\nheld out: last {HOLDOUT:.0%} of {take.name} ({n / gt.fps:.1f} s), trained on the first {cut_s:.1f} s; "
        f"{args.epochs} epochs; seeds {' '.join(map(str, args.seeds))}: mean (worst seed)"
    )
    print("\n".join(table(runs, args.models)))
    print(f"results: {out / 'heldout.json'}")


if __name__ == "__main__":
    main()
