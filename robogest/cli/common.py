"""Arguments and steps shared by several subcommands."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.cli import checks

if TYPE_CHECKING:  # imported lazily: `robogest --help` must not load numpy
    from robogest.speech.types import Speech


def add_speech_args(p: argparse.ArgumentParser, text_positional: bool = True) -> None:
    """TEXT (spoken with eSpeak NG) or --audio FILE [--transcript FILE]."""
    if text_positional:
        p.add_argument("text", nargs="?", metavar="TEXT", help="sentence to speak (synthesized offline with eSpeak NG)")
    else:
        p.add_argument("--text", metavar="TEXT", help="sentence to speak (synthesized offline with eSpeak NG)")
    p.add_argument("--audio", metavar="FILE", help="speech audio instead of TEXT (WAV/FLAC/OGG/MP3, any rate)")
    p.add_argument(
        "--transcript",
        metavar="FILE",
        help="words for --audio: Praat .TextGrid (words tier), .json word timings, or plain .txt",
    )
    p.add_argument("--voice", help="eSpeak NG voice for TEXT (default: en-us)")
    p.add_argument(
        "--wpm",
        type=checks.number(80, 450, integer=True),
        help="speaking rate for TEXT, words/min, 80-450 (default: 160)",
    )


#: Named styles for ``--style``: the ``--amount`` each stands for.
STYLES = {"calm": 0.5, "neutral": 1.0, "lively": 1.5}


def add_gesture_args(p: argparse.ArgumentParser) -> None:
    """Designer controls of the default generator: how much it gestures and with which units."""
    p.add_argument("--amount", type=float, metavar="X", help="gesture size and frequency, 0-2 (default 1; 0 = none)")
    p.add_argument("--style", choices=sorted(STYLES), help="named amount: calm 0.5, neutral 1, lively 1.5")
    p.add_argument(
        "--gestures",
        default="auto",
        metavar="none|DIR|FILE",
        help="'none' keeps only idle breathing and the rest pose; a folder or YAML file of gesture units adds "
        "to (or replaces by name) the built-in ones (also: $ROBOGEST_GESTURES). In TEXT, ^gesture(NAME) before a "
        "word pins unit NAME to it",
    )
    p.add_argument(
        "--semantic",
        choices=["keywords", "embedding"],
        default="keywords",
        help="how semantic gestures are chosen: trigger words (default) or, with the learn extra, also by "
        "sentence-embedding similarity to each unit's meaning",
    )


def generator_options(args: argparse.Namespace) -> dict:
    """Keyword options for ``make_generator`` from the gesture arguments (checked: one line per mistake)."""
    from robogest.errors import InputError

    opts: dict = {}
    checkpoint = getattr(args, "checkpoint", None)
    if checkpoint and args.generator == "rhythm":
        raise InputError("--checkpoint is for learned generators; the default 'rhythm' generator needs none")
    style, amount = getattr(args, "style", None), getattr(args, "amount", None)
    gestures, semantic = getattr(args, "gestures", "auto"), getattr(args, "semantic", "keywords")
    if amount is not None and style is not None:
        raise InputError("give --amount or --style, not both")
    amount = STYLES[style] if style else amount
    custom = amount is not None or gestures != "auto" or semantic != "keywords"
    if custom and args.generator != "rhythm":
        raise InputError(
            f"--amount, --style, --gestures and --semantic are options of the 'rhythm' generator, "
            f"not {args.generator!r}"
        )
    if checkpoint:
        opts["checkpoint"] = checkpoint
    if amount is not None:
        if not 0.0 <= amount <= 2.0:
            raise InputError(f"--amount must be within [0, 2], got {amount}")
        opts["amount"] = float(amount)
    if semantic != "keywords":
        opts["semantic"] = semantic
    if gestures == "none":
        opts["gestures"] = "none"
    elif gestures != "auto":
        from robogest.generators import lexicon as lx

        path = Path(gestures)
        if not path.exists():
            raise InputError(f"--gestures {path}: no such folder or file; give 'none' or a folder of gesture YAMLs")
        opts["repertoire"] = lx.repertoire_with(path)
    return opts


def speech_inputs(args: argparse.Namespace) -> dict[str, str | list[str] | None]:
    """The files :func:`speech_from_args` and the generator read, by flag, for
    :func:`robogest.cli.checks.check_outputs`: the audio and transcript, and the gesture files."""
    return {"--audio": args.audio, "--transcript": args.transcript, "--gestures": gesture_files(args)}


def gesture_files(args: argparse.Namespace) -> list[str]:
    """The gesture YAML files ``--gestures`` and ``$ROBOGEST_GESTURES`` name (files, or the YAMLs in folders)."""
    import os

    given = getattr(args, "gestures", None)
    entries = [given] if given not in (None, "auto", "none") else []
    entries += [e for e in os.environ.get("ROBOGEST_GESTURES", "").split(os.pathsep) if e]
    out: list[str] = []
    for entry in map(Path, entries):
        if entry.is_dir():
            out += [str(f) for f in sorted([*entry.glob("*.yaml"), *entry.glob("*.yml")])]
        elif entry.is_file():
            out.append(str(entry))
    return out


def robot_files(name_or_path: str) -> list[str]:
    """The robot's YAML and the MJCF files of its model's folder (the model and the files it includes), which no
    output may overwrite; empty when the robot does not load (the command reports that itself)."""
    from robogest.errors import ConfigError
    from robogest.robot.registry import find_robot

    try:
        robot = find_robot(name_or_path)
    except ConfigError:
        return [name_or_path] if Path(name_or_path).is_file() else []
    return [str(robot.path), *(str(f) for f in sorted(robot.model_path.parent.glob("*.xml")))]


def speech_from_args(args: argparse.Namespace, units: Mapping[str, object] | None = None) -> Speech:
    """The speech the arguments ask for; ``units``: the generator's gesture units, to check TEXT's tags against."""
    from robogest.errors import InputError
    from robogest.pipeline import load_speech_input

    if args.audio is not None and (args.voice is not None or args.wpm is not None):
        raise InputError("--voice and --wpm are for TEXT spoken by eSpeak NG; --audio is already spoken")
    return load_speech_input(
        text=args.text, audio=args.audio, transcript=args.transcript, voice=args.voice or "en-us",
        words_per_minute=args.wpm or 160, lenient=getattr(args, "lenient", False), units=units,
    )  # fmt: skip


def ensure_audio_file(speech: Speech, beside: Path) -> str:
    """Path of the speech audio on disk; synthesized speech is written next to ``beside`` as .wav."""
    if speech.audio_path is not None:
        return str(speech.audio_path)
    from robogest.speech import write_wav

    wav = beside.with_suffix(".wav")
    wav.parent.mkdir(parents=True, exist_ok=True)
    write_wav(speech, wav)
    return str(wav)


# Output that scripts can read: tables on a terminal, tab-separated lines when piped, JSON on request.


def add_json_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of tables (for scripts)")


def print_json(data: object) -> None:
    """``data`` as indented JSON on stdout; numpy scalars/arrays and paths are converted."""
    import json

    def convert(x: object) -> object:
        if hasattr(x, "tolist"):  # numpy scalar or array
            return x.tolist()
        if isinstance(x, Path):
            return str(x)
        raise TypeError(f"cannot write {type(x).__name__} as JSON")

    print(json.dumps(data, indent=2, default=convert))


@dataclass
class TextTable:
    """A titled table of strings. Cells and title are rich markup (``[red]...[/red]``, stripped when piped):
    pass data through ``rich.markup.escape``."""

    title: str
    columns: Sequence[str]
    rows: list[Sequence[str]] = field(default_factory=list)
    right_aligned: Sequence[str] = ()


def _plain(markup: str) -> str:
    from rich.text import Text

    return Text.from_markup(markup).plain


def print_table(table: TextTable) -> None:
    """A drawn table on a terminal; when stdout is a pipe or file, stable tab-separated lines.

    Piped form: ``# title``, then the header, then one line per row; markup stripped, nothing wrapped or
    truncated, so ``cut -f1`` or ``awk -F'\\t'`` read it.
    """
    if not sys.stdout.isatty():
        print(f"# {_plain(table.title)}")
        for row in (table.columns, *table.rows):
            print("\t".join(_plain(str(c)).replace("\t", " ") for c in row))
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title=table.title)
    for col in table.columns:
        t.add_column(col, justify="right" if col in table.right_aligned else "left")
    for row in table.rows:
        t.add_row(*(str(c) for c in row))
    Console().print(t)


def print_text(markup: str) -> None:
    """A line of text with rich markup: styled on a terminal, plain (never wrapped) when piped."""
    if not sys.stdout.isatty():
        print(_plain(markup))
        return
    from rich.console import Console

    Console().print(markup)
