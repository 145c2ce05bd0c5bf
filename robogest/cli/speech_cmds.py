"""``robogest analyze`` and ``robogest generate``: the speech and generator stages on their own."""

from __future__ import annotations

import argparse
from pathlib import Path

from robogest.cli import checks
from robogest.cli.common import (
    add_gesture_args,
    add_json_flag,
    add_speech_args,
    generator_options,
    print_json,
    speech_from_args,
    speech_inputs,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "analyze",
        help="speech features, beats and silent spans of an audio file or a sentence",
        description="Print a summary of the speech front-end's output (duration, words, beats, silent spans) "
        "and optionally save every frame feature to an .npz file.",
    )
    p.add_argument("audio_file", nargs="?", metavar="AUDIO", help="audio file (or use --text)")
    add_speech_args(p, text_positional=False)
    p.add_argument("--save-features", metavar="FILE.npz", help="write mel, MFCC, RMS, pitch, word features, beats")
    add_json_flag(p)
    p.set_defaults(func=run_analyze)

    g = sub.add_parser(
        "generate",
        help="generate gesture motion (BVH or SMPL-X) from speech, without a robot",
        description="Run the speech front-end and a gesture generator; write the canonical human motion as BVH "
        "(FILE.bvh) or as SMPL-X parameters in BEAT2's layout (FILE.npz: upper body filled, the rest zero), which "
        "`robogest eval --fgd-weights` scores.",
    )
    add_speech_args(g, text_positional=False)
    g.add_argument(
        "--out", required=True, metavar="FILE.bvh|FILE.npz", help="motion file to write: BVH, or SMPL-X (.npz)"
    )
    g.add_argument(
        "--generator",
        default="rhythm",
        help="gesture generator: rhythm, gesticulator, rhythmic, s2ag, or an installed plugin's (default: %(default)s)",
    )
    g.add_argument(
        "--seed", type=checks.seed, default=0, help="random seed, 0..2**32-1; same input + seed = same motion"
    )
    add_gesture_args(g)
    g.add_argument("--checkpoint", metavar="FILE", help="trained weights for a learned generator")
    g.add_argument(
        "--plot",
        metavar="FILE.png",
        help="also plot wrist trajectories with beats and silent spans (needs the plot extra)",
    )
    checks.needs_extra(g, "--plot", "plot")
    g.set_defaults(func=run_generate)


def run_analyze(args: argparse.Namespace) -> int:
    from robogest.errors import InputError
    from robogest.speech import save_features, speech_summary

    if args.audio_file and args.audio:
        raise InputError("give the audio file once: either as AUDIO or as --audio")
    args.audio = args.audio or args.audio_file
    checks.check_outputs({"--save-features": args.save_features}, speech_inputs(args))
    if args.save_features and not Path(args.save_features).parent.is_dir():  # save_features creates no folders
        raise InputError(f"--save-features {args.save_features}: the folder does not exist; create it first")
    speech = speech_from_args(args)
    summary = speech_summary(speech)
    if args.save_features:
        save_features(speech, args.save_features)
    if args.json:
        print_json({**summary, "features_file": args.save_features})
        return 0
    for k, v in summary.items():
        print(f"{k:>24}: {v}")
    if args.save_features:
        print(f"features written to {args.save_features}")
    return 0


def run_generate(args: argparse.Namespace) -> int:
    from robogest.errors import InputError
    from robogest.generators import make_generator
    from robogest.motion import save_motion

    checks.check_outputs(
        {"--out": args.out, "--plot": args.plot}, {**speech_inputs(args), "--checkpoint": args.checkpoint}
    )
    if Path(args.out).suffix.lower() not in (".bvh", ".npz"):  # before any work (it wrote BVH into any name)
        raise InputError(f"--out {args.out}: name the motion file .bvh (BVH) or .npz (SMPL-X parameters)")
    speech = speech_from_args(args)
    motion = make_generator(args.generator, **generator_options(args)).generate(speech, seed=args.seed)
    save_motion(motion, Path(args.out))
    print(f"{motion.n_frames} frames at {motion.fps:g} fps ({motion.duration_s:.2f} s) written to {args.out}")
    if args.plot:
        from robogest.viz.plot import plot_motion

        plot_motion(args.plot, motion, speech)
        print(f"plot written to {args.plot}")
    return 0
