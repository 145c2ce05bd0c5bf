"""Rhythmic Gesticulator inference speed on CPU (target >= 20x real time), plus PMB and lexeme entropy.

Usage: ``.venv/bin/python benchmarks/bench_rhythmic.py [--checkpoint FILE.pt] [--seconds 20] [--threads 2]``.
Without a checkpoint a short run on the synthetic fixture dataset is trained first (paper-size default config, one
epoch per stage, ``hash-test`` text encoder), so the timing covers the full-width model. The speech is analysed
once, outside the timing: the number is the generator's own cost (beat blocks with time-scaled audio, interpreters,
generator, denormalisation, smoothing). The same speech is also timed with the audio blocks resampled from the
log-mel frames instead of time-scaled (``audio_tsm=False``), in the same run, to show what TSM costs.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--checkpoint")
    ap.add_argument("--seconds", type=float, default=20.0, help="speech length, s")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    import numpy as np
    import torch

    from robogest.eval import lexeme_entropy, motion_beats, pmb
    from robogest.generators.learned.rhythmic import RhythmicGenerator
    from robogest.speech import analyze, synthesize

    torch.set_num_threads(args.threads)
    ckpt = args.checkpoint
    if ckpt is None:
        from robogest.data import make_fixture_dataset
        from robogest.generators.learned import train_model
        from robogest.learn.trainer import TrainConfig

        tmp = Path(tempfile.mkdtemp(prefix="bench_rhythmic_"))
        data = make_fixture_dataset(tmp / "ds", n_takes=2, duration_s=8.0)
        cfg = TrainConfig(
            model="rhythmic", data=str(data), out=str(tmp / "run"), epochs=4, batch_size=16,
            window_stride=10, val_fraction=0.0, device="cpu", cache_dir=str(tmp / "cache"),
            text_encoder="hash-test", text_encoder_kwargs={"dim": 16},
        )  # fmt: skip
        ckpt = train_model(cfg, log=lambda s: None)
    gen = RhythmicGenerator(ckpt)
    base = synthesize("Hello there, I am a robot and I like to wave my arms while I talk ... " * 3)
    reps = max(1, int(np.ceil(args.seconds / base.duration_s)))
    audio = np.tile(base.audio, reps)[: round(args.seconds * base.sr)]
    words = [
        type(w)(w.text, w.start_s + r * base.duration_s, w.end_s + r * base.duration_s, w.syllables)
        for r in range(reps)
        for w in base.words
        if w.end_s + r * base.duration_s <= args.seconds
    ]

    def timed(speech) -> tuple[float, object]:
        gen.generate(speech)  # warm-up
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            motion = gen.generate(speech)
            times.append(time.perf_counter() - t0)
        return statistics.median(times), motion

    tsm_config = gen.config
    for label, ws in (("text", words), ("audio-only", [])):
        speech = analyze(audio, base.sr, ws)
        gen.config = dataclasses.replace(tsm_config, audio_tsm=False)
        med_frames, _ = timed(speech)
        gen.config = tsm_config
        med, motion = timed(speech)
        plan = gen.generate_blocks(speech)
        score = pmb(motion_beats(motion.positions(), motion.fps), speech.beats_s)
        ent = lexeme_entropy(plan.lexemes, gen.config.lexicon_size)
        print(
            f"{label:10s} {speech.duration_s:.1f} s speech, {len(plan.lexemes)} blocks: median {med * 1000:.0f} ms "
            f"-> {speech.duration_s / med:.0f}x real time ({args.threads} threads); without TSM "
            f"{med_frames * 1000:.0f} ms ({med / med_frames:.2f}x faster than with); PMB {score:.1f} %, "
            f"lexeme entropy {ent['entropy_nats']:.2f} nats"
        )


if __name__ == "__main__":
    main()
