"""Arguments and steps shared by several subcommands."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

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
    p.add_argument("--voice", default="en-us", help="eSpeak NG voice for TEXT (default: %(default)s)")
    p.add_argument("--wpm", type=int, default=160, help="speaking rate for TEXT, words/min (default: %(default)s)")


def speech_from_args(args: argparse.Namespace) -> Speech:
    from robogest.pipeline import load_speech_input

    return load_speech_input(
        text=args.text, audio=args.audio, transcript=args.transcript, voice=args.voice, words_per_minute=args.wpm
    )


def ensure_audio_file(speech: Speech, beside: Path) -> str:
    """Path of the speech audio on disk; synthesized speech is written next to ``beside`` as .wav."""
    if speech.audio_path is not None:
        return str(speech.audio_path)
    from robogest.speech import write_wav

    wav = beside.with_suffix(".wav")
    wav.parent.mkdir(parents=True, exist_ok=True)
    write_wav(speech, wav)
    return str(wav)
