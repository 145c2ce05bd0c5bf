"""Held-out evidence for the learned generators on one real take (issue 15 §5).

Usage::

    .venv/bin/python benchmarks/bench_learned_heldout.py --take ../shared/data/beat2/2_scott_0_1_1 \
        [--models gesticulator rhythmic s2ag] [--epochs 20] [--out runs/heldout] [--threads 2]

Each model trains on the take's first 70 % (the trainer splits a one-take dataset in time: ``--val-fraction 0.3``
holds out the last 30 % as its validation take, so the logged held-out loss is on unseen speech) and then
generates the last 30 % free-running from its audio and transcript alone. Two baselines get the same evaluation:
the mean training pose held still, and a replay of a random stretch of the training motion of the same length.
Printed per model: the held-out loss of ``best.pt``, acceleration and jerk ratios to the real motion, MAJE, and
stroke sync against the speech beats (PMB with its chance correction: z over circular time shifts). ``beats both``
means a lower MAJE than both baselines and a higher beat-sync z than both.

One take of about a minute cannot show that a model generalises across speakers or content; it can show whether
training on real speech runs end to end and whether the held-out motion is better than trivial baselines.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

HOLDOUT = 0.3


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


def _evaluate(motion, gt, speech) -> dict:
    from robogest.eval.report import evaluate_motion

    n = min(motion.n_frames, gt.n_frames)
    r = evaluate_motion(
        motion.positions()[:n], gt.fps, list(gt.skeleton.names), gt.positions()[:n], speech.beats_s, n_shifts=50
    )
    return {
        "accel_ratio": r["ratio_to_gt"]["acceleration_ratio"],
        "jerk_ratio": r["ratio_to_gt"]["jerk_ratio"],
        "maje_mm": r["maje_mad"]["maje_mm"],
        "pmb": r["beat_sync"]["pmb"]["score"],
        "pmb_z": r["beat_sync"]["pmb"]["z"],
        "gt_pmb_z": r["gt_beat_sync"]["pmb"]["z"],
    }


def _z(row: dict) -> float:
    """Beat-sync z; a motion without motion beats (the still mean pose) has no sync at all."""
    z = row["pmb_z"]
    return z if z == z else float("-inf")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--take", required=True, help="path without suffix: TAKE.wav, TAKE.npz|.bvh, TAKE.TextGrid")
    ap.add_argument("--models", nargs="+", default=["gesticulator", "s2ag", "rhythmic"])
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--text-encoder", default="minilm")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import numpy as np
    import torch

    from robogest.data.features import expmap_to_motion, motion_to_expmap
    from robogest.generators import make_generator
    from robogest.generators.learned import train_model
    from robogest.learn.trainer import TrainConfig
    from robogest.motion import load_motion

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
    n = min(gt.n_frames, speech.n_frames)

    rows = {}
    rows["baseline: mean pose"] = _evaluate(
        expmap_to_motion(np.repeat(poses[:cut].mean(0, keepdims=True), n, 0), gt.fps), gt, speech
    )
    start = np.random.default_rng(args.seed).integers(0, max(1, cut - n))
    rows["baseline: replay"] = _evaluate(expmap_to_motion(poses[start : start + n], gt.fps), gt, speech)

    for model in args.models:
        cfg = TrainConfig(
            model=model, data=str(data), out=str(out / model), epochs=args.epochs, val_fraction=HOLDOUT,
            device="cpu", seed=args.seed, text_encoder=args.text_encoder, cache_dir=str(out / "cache"),
            window_stride=2,
        )  # fmt: skip
        best = train_model(cfg, log=lambda s, m=model: print(f"[{m}] {s}", flush=True))
        history = json.loads((out / model / "history.json").read_text())
        gen = make_generator(model, checkpoint=str(best))
        motion = gen.generate(speech, seed=args.seed)
        row = _evaluate(motion, gt, speech)
        row["held_out_loss"] = min(h["val_loss"] for h in history if "val_loss" in h)
        rows[model] = row

    base = [rows["baseline: mean pose"], rows["baseline: replay"]]
    print(f"\nheld out: last {HOLDOUT:.0%} of {take.name} ({n / 20:.1f} s), trained on the first {cut_s:.1f} s")
    print("| | held-out loss | accel ratio | jerk ratio | MAJE mm | PMB | PMB z | beats both |")
    print("|---|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        both = (
            "-" if name.startswith("baseline")
            else "yes" if all(r["maje_mm"] < b["maje_mm"] and _z(r) > _z(b) for b in base) else "no"
        )  # fmt: skip
        loss = f"{r['held_out_loss']:.3f}" if "held_out_loss" in r else "-"
        print(
            f"| {name} | {loss} | {r['accel_ratio']:.2f} | {r['jerk_ratio']:.2f} | {r['maje_mm']:.1f} | "
            f"{r['pmb']:.2f} | {r['pmb_z']:.2f} | {both} |"
        )
    print(f"(real motion: PMB z {rows['baseline: mean pose']['gt_pmb_z']:.2f})")
    (out / "heldout.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
