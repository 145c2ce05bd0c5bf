"""``robogest train``: train a learned generator on a speech-gesture dataset folder."""

from __future__ import annotations

import argparse
import json
import os

from robogest.cli import checks
from robogest.errors import InputError
from robogest.learn.dist import DEFAULT_TIMEOUT_S  # no torch at import


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "train",
        help="train a learned gesture generator (needs robogest[learn])",
        description="Train a learned generator on a dataset folder (GENEA/Trinity, BEAT2, or NAME.wav + "
        "NAME.bvh|.npz pairs). Writes OUT/last.pt (every epoch), OUT/best.pt (lowest held-out loss, on a "
        "free-running rollout for the autoregressive models) and "
        "OUT/history.json; either .pt works with `robogest speak --generator NAME --checkpoint FILE`. "
        "Launch with torchrun for multi-GPU DistributedDataParallel training. The rhythmic model trains its stages "
        "(audio encoder, lexicon, generator, interpreters) one after another, so it needs --epochs >= 4.",
    )
    p.add_argument("--model", default="gesticulator", help="model to train (default: %(default)s)")
    p.add_argument("--data", required=True, metavar="DIR", help="dataset folder")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder for checkpoints")
    p.add_argument(
        "--epochs", type=checks.positive_int(100_000), default=20, help="total epochs (default: %(default)s)"
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from OUT/last.pt (without it, an OUT that holds a run is refused)",
    )
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed (default: %(default)s)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="default: %(default)s")
    p.add_argument(
        "--batch-size", type=checks.positive_int(1_000_000), default=64, help="global batch size (default: %(default)s)"
    )
    p.add_argument(
        "--lr", type=checks.number(1e-12, 10.0),
        help="Adam learning rate (default: the model's paper value: gesticulator 1e-4, rhythmic "
        "3e-4; s2ag always uses its own two rates, see --set lr_generator=...)",
    )  # fmt: skip
    p.add_argument(
        "--val-fraction", type=checks.number(0.0, 0.9), default=0.1,
        help="share of takes for validation (a folder with BEAT2's train_test_split.csv uses its split instead)",
    )  # fmt: skip
    p.add_argument(
        "--window-stride", type=checks.positive_int(1_000_000), default=5, help="frames between training windows"
    )
    p.add_argument("--text-encoder", default="minilm", help="text encoder name (default: %(default)s)")
    p.add_argument(
        "--cache-dir", metavar="DIR",
        help="feature cache, reused across runs; the rhythmic model keeps its time-scaled audio blocks there too "
        "(default: ~/.cache/robogest/features)",
    )  # fmt: skip
    p.add_argument(
        "--dist-timeout-s", type=checks.number(1.0, 1e7), default=DEFAULT_TIMEOUT_S, metavar="S",
        help="under torchrun: how long a rank waits for the others (e.g. while rank 0 builds the caches) before "
        "the job fails (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", dest="options",
        help="model option, repeatable: a field of the model's config class (GesticulatorConfig, RhythmicConfig, "
        "S2AGConfig), VALUE as JSON or a bare word, e.g. --set lexicon_size=30 --set stages=joint; an unknown "
        "option is refused with the list of known ones",
    )  # fmt: skip
    p.set_defaults(func=run)


def parse_options(items: list[str]) -> dict[str, object]:
    """``["KEY=VALUE", ...]`` -> dict; VALUE is JSON (number, true/false, list) or else a plain string."""
    out: dict[str, object] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. --set lexicon_size=30")
        try:
            out[key.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[key.strip()] = raw
    return out


def run(args: argparse.Namespace) -> int:
    from robogest.generators.learned import get_model_spec
    from robogest.learn.trainer import TrainConfig, train

    if os.path.realpath(args.out) == os.path.realpath(args.data):
        raise InputError(
            f"--out {args.out} is the dataset folder --data {args.data}; keep checkpoints apart from the data"
        )
    checks.check_outputs({}, folders={"--out": args.out, "--cache-dir": args.cache_dir})
    kwargs = {"dim": 16} if args.text_encoder == "hash-test" else {}
    cfg = TrainConfig(
        model=args.model,
        data=args.data,
        out=args.out,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        device=args.device,
        resume=args.resume,
        val_fraction=args.val_fraction,
        window_stride=args.window_stride,
        text_encoder=args.text_encoder,
        text_encoder_kwargs=kwargs,
        cache_dir=args.cache_dir,
        dist_timeout_s=args.dist_timeout_s,
        model_overrides=parse_options(args.options),
    )
    best = train(cfg, get_model_spec(args.model))
    if os.environ.get("RANK", "0") == "0":  # one line for a torchrun job
        print(f"best checkpoint: {best}")
    return 0
