"""Held-out evidence for the learned generators on one real take (issues 15 §5 and 33 §4).

Usage::

    .venv/bin/python benchmarks/bench_learned_heldout.py --take ../shared/data/beat2/2_scott_0_1_1 \
        [--models gesticulator s2ag rhythmic] [--epochs 8] [--seeds 0 1 2] [--out runs/heldout] [--threads 2]
    .venv/bin/python benchmarks/bench_learned_heldout.py --report runs/h0/heldout.json runs/h1/heldout.json ...

The take is split in time into train / validation / test (:data:`SPLIT`: the first 60 %, the next 15 %, the last
25 %; :func:`split_frames`). The trainer only ever sees the first 75 %: the benchmark writes a copy of the take cut
there (recording, motion, words as ``.tsv``) and trains with ``--val-fraction`` = 15 / 75, so the trainer's own
one-take split (:func:`robogest.data.prep.split_takes`) holds out the validation 15 %, on which ``best.pt`` is
chosen. Each model then generates the test 25 % free-running from its audio and transcript alone; nothing the test
part holds (motion, words, stressed vowels) influences training or selection. Two baselines get the same
evaluation: the mean training pose held still, and a replay of a random stretch of the training motion of the
same length (a new stretch per seed). Every seed trains every model afresh from its own seed, so seeds can also
run as separate processes with their own ``--out``, pooled by ``--report`` (bit-identical tables on the BEAT2
sample); the tables give the mean over seeds
and, in brackets, the worst seed.

Printed per model and baseline (all on the test part unless said otherwise):

- the validation loss of ``best.pt`` (each model's own selection objective on the validation part, not
  comparable across models; the only number here that selection saw);
- acceleration and jerk ratios to the real test motion on the model's paper joint set
  (:data:`robogest.eval.kinematics.PAPER_JOINT_SETS`, root translation removed): Gesticulator on ``gesticulator``
  (its §5.1 upper body), S2AG on ``s2ag`` (the TED joints of its §5.2), the Rhythmic Gesticulator on
  ``gesticulator`` (its paper reports no acceleration or jerk; on motion capture, which this take is, it models
  the Trinity upper body with a fixed root, which that set is). Baselines get a row per set;
- MAJE (mm, all joints; Rhythmic Gesticulator Table 1);
- the wrist-speed histogram distance (Hellinger, 1 cm/s bins, both wrists pooled; Gesticulator §6.1.2 and
  :func:`robogest.eval.kinematics.wrist_speed_comparison`), a distribution measure: 0 = the same speed
  distribution as the real test motion, 1 = disjoint;
- stroke sync (:func:`robogest.eval.beats.stroke_sync`: wrist-speed peaks during speech followed within 0.2 s
  by a stressed-vowel onset of the take's TextGrid, the validated events; z over circular time shifts).

The human reference: the whole real training part against the real test part (the floor of the distribution
measure and of the acceleration and jerk ratios: real motion of the same speaker in other minutes), and the replay
baseline, which is real motion scored frame by frame (MAJE, sync). A second table counts, per criterion, the seeds
in which each model beats each baseline (ratios closer to 1 in ``|log ratio|``, lower MAJE, lower Hellinger,
higher stroke-sync z; no strokes = no sync), with the replay's own count against the mean pose as the reference
for what real motion achieves on that criterion.

One take of about a minute cannot show that a model generalises across speakers or content; it can show whether
training on real speech runs end to end and how the test motion compares with trivial baselines and real motion.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: Fractions of the take, in time order: train, validation (selection of ``best.pt``), test (reported).
SPLIT = (0.60, 0.15, 0.25)
#: Each model's paper joint set for acceleration and jerk (see the module docstring for the Rhythmic Gesticulator).
MODEL_SET = {"gesticulator": "gesticulator", "s2ag": "s2ag", "rhythmic": "gesticulator"}
SET_LABEL = {"gesticulator": "Gesticulator (13)", "s2ag": "S2AG (10)"}
MODEL_LABEL = {"gesticulator": "Gesticulator", "s2ag": "S2AG", "rhythmic": "Rhythmic Gesticulator"}
CRITERIA = ("accel", "jerk", "MAJE", "Hellinger", "sync")

Row = dict[str, Any]


def split_frames(n_frames: int, split: tuple[float, float, float] = SPLIT) -> tuple[int, int]:
    """Frame indices ``(val_start, test_start)`` cutting ``n_frames`` into train / validation / test in time.

    Train is ``[0, val_start)``, validation ``[val_start, test_start)``, test ``[test_start, n_frames)``; each
    is at least one frame, and the fractions must be positive and sum to 1.
    """
    if len(split) != 3 or min(split) <= 0 or abs(sum(split) - 1.0) > 1e-9:
        raise ValueError(f"split {split}: need three positive fractions (train, val, test) summing to 1")
    val_start = round(n_frames * split[0])
    test_start = round(n_frames * (split[0] + split[1]))
    if not 0 < val_start < test_start < n_frames:
        raise ValueError(f"{n_frames} frames are too few to split {split} with a frame in each part")
    return val_start, test_start


def trainer_val_fraction(val_start: int, test_start: int) -> float:
    """``--val-fraction`` that makes the trainer's one-take split of the first ``test_start`` frames validate on
    ``[val_start, test_start)`` (up to its rounding of one frame)."""
    return (test_start - val_start) / test_start


def _write_trimmed_take(wav: Path, mfile: Path, tg: Path, end_s: float, data: Path) -> None:
    """The take's first ``end_s`` seconds in ``data``: recording, motion (``.npz`` or ``.bvh``) and the words that
    end by then as a ``.tsv`` (the trainer reads only the words tier of a TextGrid, which this keeps)."""
    import numpy as np
    import soundfile as sf

    from robogest.speech.transcript import read_transcript

    audio, sr = sf.read(str(wav), dtype="float32")
    sf.write(str(data / wav.name), audio[: round(end_s * sr)], sr, subtype="FLOAT")
    if mfile.suffix == ".npz":
        with np.load(mfile, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        n = arrays["poses"].shape[0]
        keep = round(end_s * float(arrays["mocap_frame_rate"]))
        np.savez(data / mfile.name, **{k: v[:keep] if v.ndim and v.shape[0] == n else v for k, v in arrays.items()})
    else:
        head, _, frames = mfile.read_text().partition("\nMOTION\n")
        lines = frames.splitlines()
        frame_s = float(lines[1].split(":")[1])
        keep = round(end_s / frame_s)
        body = [f"Frames: {keep}", lines[1], *lines[2 : 2 + keep]]
        (data / mfile.name).write_text(head + "\nMOTION\n" + "\n".join(body) + "\n")
    words = [w for w in read_transcript(tg).words if w.end_s <= end_s]
    rows = "".join(f"{w.start_s:.4f}\t{w.end_s:.4f}\t{w.text}\n" for w in words)
    (data / tg.with_suffix(".tsv").name).write_text(rows, encoding="utf-8")


def _test_speech(wav: Path, transcript: Path, cut_s: float):
    """The take from ``cut_s`` on, analysed as the generators see speech at run time."""
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


def _distribution(motion, gt) -> Row:
    """Paper-set acceleration/jerk ratios and the wrist-speed Hellinger distance; lengths may differ."""
    from robogest.eval.kinematics import paper_statistics, wrist_speed_comparison
    from robogest.eval.report import wrist_indices

    names = list(gt.skeleton.names)
    pred, real = motion.positions(), gt.positions()  # (T, J, 3) metres
    row: Row = {"hellinger": wrist_speed_comparison(pred, real, gt.fps, wrist_indices(names))["hellinger"]}
    for s, e in paper_statistics(pred, gt.fps, names, real).items():
        row[f"{s}_accel"] = e["ratio_to_gt"]["acceleration_ratio"]
        row[f"{s}_jerk"] = e["ratio_to_gt"]["jerk_ratio"]
    return row


def _evaluate(motion, gt, onsets, spans) -> Row:
    """All criteria of ``motion`` against the real test motion ``gt`` (frame-aligned, the shorter length)."""
    from robogest.eval.beats import stroke_sync
    from robogest.eval.kinematics import maje_mad
    from robogest.eval.report import wrist_indices
    from robogest.motion.human_motion import HumanMotion

    n = min(motion.n_frames, gt.n_frames)
    motion, gt = (HumanMotion(m.fps, m.rotations[:n], m.root_pos_m[:n], m.skeleton) for m in (motion, gt))
    pred, real = motion.positions(), gt.positions()  # (n, J, 3) metres
    sync = stroke_sync(pred[:, wrist_indices(list(gt.skeleton.names))], gt.fps, onsets, spans)
    return {
        **_distribution(motion, gt),
        "maje_mm": maje_mad(pred, real, gt.fps)["maje_mm"],
        "sync_z": sync["z"],
        "sync_hit": sync["hit"],
    }


def _off(ratio: float) -> float:
    """How far a ratio is from 1, symmetric for half and double; a still motion (ratio 0) is infinitely far."""
    return abs(math.log(ratio)) if ratio > 0 else math.inf


def _z(row: Row) -> float:
    """Stroke-sync z; a motion without strokes (the still mean pose) has no sync at all."""
    z = row["sync_z"]
    return z if z == z else -math.inf


def beats(row: Row, base: Row, joint_set: str) -> dict[str, bool]:
    """Per criterion, whether ``row`` is strictly better than the baseline ``base`` (see the module docstring)."""
    return {
        "accel": _off(row[f"{joint_set}_accel"]) < _off(base[f"{joint_set}_accel"]),
        "jerk": _off(row[f"{joint_set}_jerk"]) < _off(base[f"{joint_set}_jerk"]),
        "MAJE": row["maje_mm"] < base["maje_mm"],
        "Hellinger": row["hellinger"] < base["hellinger"],
        "sync": _z(row) > _z(base),
    }


def _agg(values: list[float], worst: Callable[[list[float]], float], fmt: str) -> str:
    """``mean (worst)`` over seeds; just the value where every seed gives the same."""
    vals = [v for v in values if v == v]
    if not vals:
        return "n/a"
    mean = sum(vals) / len(vals)
    return fmt.format(mean) if min(vals) == max(vals) else f"{fmt.format(mean)} ({fmt.format(worst(vals))})"


def _far(vals: list[float]) -> float:
    """The worst ratio is the one farthest from 1."""
    return max(vals, key=_off)


def table(runs: list[dict[str, Row]], models: list[str]) -> list[str]:
    """Markdown rows of the test-split table from per-seed results ``runs`` (each: row name -> metrics)."""
    lines = [
        "| | joint set | val loss (selection) | accel ratio | jerk ratio | MAJE mm | wrist-speed Hellinger "
        "| stroke sync z |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def line(name: str, key: str, joint_set: str | None, loss: str) -> str:
        """One row; ``joint_set`` None for motions whose ratios are the same on every set (real: 1, still: 0)."""
        label = "any" if joint_set is None else SET_LABEL[joint_set]
        joint_set = joint_set or next(iter(SET_LABEL))
        rs = [r[key] for r in runs]
        acc = _agg([r[f"{joint_set}_accel"] for r in rs], _far, "{:.2f}")
        jerk = _agg([r[f"{joint_set}_jerk"] for r in rs], _far, "{:.2f}")
        maje = _agg([r.get("maje_mm", math.nan) for r in rs], max, "{:.1f}")
        hel = _agg([r["hellinger"] for r in rs], max, "{:.3f}")
        z = _agg([r.get("sync_z", math.nan) for r in rs], min, "{:.2f}")
        z = "n/a (no strokes)" if z == "n/a" and "sync_z" in rs[0] else z.replace("n/a", "-")
        maje = maje.replace("n/a", "-")
        return f"| {name} | {label} | {loss} | {acc} | {jerk} | {maje} | {hel} | {z} |"

    lines.append(line("real test motion", "real", None, "-"))
    for s in SET_LABEL:
        lines.append(line("reference: real training motion (whole 60 %)", "real train", s, "-"))
    lines.append(line("baseline: mean training pose", "mean pose", None, "-"))
    for s in SET_LABEL:
        lines.append(line("baseline: replay of training motion", "replay", s, "-"))
    for m in models:
        loss = _agg([r[m]["val_loss"] for r in runs], max, "{:.3f}")
        lines.append(line(MODEL_LABEL[m], m, MODEL_SET[m], loss))
    return lines


def criteria_table(runs: list[dict[str, Row]], models: list[str]) -> list[str]:
    """Markdown rows: per criterion, in how many seeds each motion beats the mean pose and the replay, and in how
    many its Hellinger distance is within the human floor (real training motion against the real test motion)."""
    k = len(runs)
    lines = [
        f"| seeds of {k} better than: mean pose / replay | " + " | ".join(CRITERIA) + " | Hellinger <= human floor |",
        "|---" * (len(CRITERIA) + 2) + "|",
    ]

    def floor(key: str) -> str:
        return f"{sum(r[key]['hellinger'] <= r['real train']['hellinger'] for r in runs)}"

    ref = [beats(r["replay"], r["mean pose"], "gesticulator") for r in runs]
    cells = [f"{sum(b[c] for b in ref)} / -" for c in CRITERIA]
    lines.append("| replay of training motion (real motion) | " + " | ".join(cells) + f" | {floor('replay')} |")
    for m in models:
        s = MODEL_SET[m]
        vs_mean = [beats(r[m], r["mean pose"], s) for r in runs]
        vs_replay = [beats(r[m], r["replay"], s) for r in runs]
        cells = [f"{sum(b[c] for b in vs_mean)} / {sum(b[c] for b in vs_replay)}" for c in CRITERIA]
        lines.append(f"| {MODEL_LABEL[m]} | " + " | ".join(cells) + f" | {floor(m)} |")
    return lines


def _train_and_generate(model: str, seed: int, args: argparse.Namespace, out: Path, val_fraction: float, speech):
    """Train ``model`` on the trimmed take in ``out / 'data'``; its ``best.pt``'s test motion and validation loss."""
    from robogest.generators import make_generator
    from robogest.generators.learned import train_model
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig

    cfg = TrainConfig(
        model=model, data=str(out / "data"), out=str(out / f"seed{seed}" / model), epochs=args.epochs,
        val_fraction=val_fraction, device="cpu", seed=seed, text_encoder=args.text_encoder,
        cache_dir=str(out / "cache"), window_stride=2,
    )  # fmt: skip
    best = train_model(cfg, log=lambda s: print(f"[{model} seed {seed}] {s}", flush=True))
    motion = make_generator(model, checkpoint=str(best)).generate(speech, seed=seed)
    return motion, float(load_checkpoint(best)["train_state"]["best_val"])


def _parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    ap.add_argument("--take", help="path without suffix: TAKE.wav, TAKE.npz|.bvh, TAKE.TextGrid")
    ap.add_argument("--models", nargs="+", default=["gesticulator", "s2ag", "rhythmic"], choices=list(MODEL_SET))
    ap.add_argument("--epochs", type=int, default=8)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--text-encoder", default="minilm")
    ap.add_argument(
        "--report", nargs="+", metavar="JSON", help="print the tables of saved heldout.json files (e.g. one per seed, "
        "run in parallel with separate --out folders) together, instead of running"
    )  # fmt: skip
    args = ap.parse_args()
    if not args.report and not args.take:
        ap.error("--take is required (or --report JSON ...)")
    return args


def _print_report(saved: list[dict[str, Any]]) -> None:
    """The tables of one or more saved results (same take, split and models), seeds pooled."""
    header, models = saved[0]["header"], saved[0]["models"]
    if any(d["header"] != header or d["models"] != models for d in saved):
        raise SystemExit("--report: the files come from different takes, splits, epochs or models")
    seeds = [x for d in saved for x in d["seeds"]]
    runs = [r for d in saved for r in d["runs"]]
    print(f"\n{header}; seeds {' '.join(map(str, seeds))}: mean (worst seed)")
    print("\n".join(table(runs, models)))
    print()
    print("\n".join(criteria_table(runs, models)))


def main() -> None:
    args = _parse_args()
    if args.report:
        _print_report([json.loads(Path(f).read_text()) for f in args.report])
        return
    import numpy as np
    import torch

    from robogest.data.features import expmap_to_motion, motion_to_expmap
    from robogest.motion import load_motion
    from robogest.speech.transcript import read_stressed_vowels

    torch.set_num_threads(args.threads)
    take = Path(args.take)
    wav, tg = take.with_suffix(".wav"), take.with_suffix(".TextGrid")
    mfile = next(p for p in (take.with_suffix(".npz"), take.with_suffix(".bvh")) if p.is_file())
    out = Path(args.out or tempfile.mkdtemp(prefix="heldout-"))
    shutil.rmtree(out / "data", ignore_errors=True)
    (out / "data").mkdir(parents=True)

    gt_all = load_motion(mfile).resample(20.0)
    val_start, test_start = split_frames(gt_all.n_frames)
    val_s, test_s = val_start / gt_all.fps, test_start / gt_all.fps
    _write_trimmed_take(wav, mfile, tg, test_s, out / "data")
    poses = motion_to_expmap(gt_all)  # (T, J * 3)
    gt = expmap_to_motion(poses[test_start:], gt_all.fps)  # canonical root, as generated motion has
    train_motion = expmap_to_motion(poses[:val_start], gt_all.fps)
    speech = _test_speech(wav, tg, test_s)
    stressed = read_stressed_vowels(tg)
    if stressed is None:
        raise SystemExit(f"{tg}: no stress-marked phones tier; stroke sync is validated only with one")
    onsets = stressed[stressed >= test_s] - test_s  # (K,) seconds into the test part; no generator sees them
    spans = [(float(a), float(b)) for a, b in speech.silent_spans]
    n = min(gt.n_frames, speech.n_frames)

    header = (
        f"{take.name}: train 0-{val_s:.1f} s, validation (selection) {val_s:.1f}-{test_s:.1f} s, "
        f"test (reported) {test_s:.1f}-{test_s + n / gt.fps:.1f} s; {args.epochs} epochs"
    )
    runs: list[dict[str, Row]] = []
    for seed in args.seeds:
        rows = {"real": _evaluate(gt, gt, onsets, spans), "real train": _distribution(train_motion, gt)}
        rows["mean pose"] = _evaluate(
            expmap_to_motion(np.repeat(poses[:val_start].mean(0, keepdims=True), n, 0), gt.fps), gt, onsets, spans
        )
        start = np.random.default_rng(seed).integers(0, max(1, val_start - n))
        rows["replay"] = _evaluate(expmap_to_motion(poses[start : start + n], gt.fps), gt, onsets, spans)
        for model in args.models:
            val_fraction = trainer_val_fraction(val_start, test_start)
            motion, val_loss = _train_and_generate(model, seed, args, out, val_fraction, speech)
            rows[model] = {**_evaluate(motion, gt, onsets, spans), "val_loss": val_loss}
        runs.append(rows)
        saved = {"header": header, "models": args.models, "seeds": args.seeds[: len(runs)], "runs": runs}
        (out / "heldout.json").write_text(json.dumps(saved, indent=1))
    _print_report([saved])
    print(f"results: {out / 'heldout.json'}")


if __name__ == "__main__":
    main()
