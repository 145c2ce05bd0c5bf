"""How the cost of a transcript grows with its size (not a test): the words-per-second cap that refuses a runaway
transcript once counted, and silent spans as they were (each word against every frame, each span against every
word) against now (one pass over frames and words, a span against the words near it).

    .venv/bin/python benchmarks/diag_transcript_scaling.py [--hours 0.5]

Prints, per size, the seconds each takes and their ratio side by side.
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
import time
from pathlib import Path

import numpy as np
import soundfile as sf

from robogest.errors import InputError
from robogest.pipeline import load_speech_input
from robogest.speech.silence import silent_spans
from robogest.speech.types import Word


def spans_before(volume: np.ndarray, rate: float, threshold: float, duration_s: float, min_silence_s: float,
                 words: list[Word]) -> tuple[tuple[float, float], ...]:  # fmt: skip
    """:func:`silent_spans` as it was: a pass over every frame for each word, then over every word for each span."""
    from robogest.speech.silence import find_runs

    quiet = volume <= threshold
    times = np.arange(quiet.shape[0]) / rate
    for w in words:
        quiet[(times + 0.5 / rate > w.start_s) & (times - 0.5 / rate < w.end_s)] = False
    out = []
    for i0, i1 in find_runs(quiet):
        start = 0.0 if i0 == 0 else max(0.0, (i0 - 0.5) / rate)
        end = duration_s if i1 == quiet.shape[0] else min(duration_s, (i1 - 0.5) / rate)
        for w in words:
            if start - 1.0 / rate <= w.end_s <= start + 1.0 / rate and w.start_s < start:
                start = w.end_s
            if end - 1.0 / rate <= w.start_s <= end + 1.0 / rate and w.end_s > end:
                end = w.start_s
        if end - start >= min_silence_s - 1e-9:
            out.append((float(start), float(end)))
    return tuple(out)


def refusal(folder: Path) -> None:
    """An untimed transcript of growing size for 2 s of audio: refused once its words are counted."""
    sr = 16000
    t = np.arange(2 * sr) / sr
    sf.write(folder / "a.wav", 0.3 * np.sin(2 * np.pi * 200 * t) * (np.sin(2 * np.pi * 2 * t) > 0), sr)
    print("transcript bytes   seconds to refuse")
    for size in (100_000, 400_000, 8_000_000):
        (folder / "w.txt").write_text("hello robot " * (size // 12))
        t0 = time.perf_counter()
        with contextlib.suppress(InputError):
            load_speech_input(text=None, audio=str(folder / "a.wav"), transcript=str(folder / "w.txt"))
        print(f"{size:>15,d}   {time.perf_counter() - t0:8.3f}")


def spans(hours: float) -> None:
    """Silent spans of a take of ``hours`` at 100 frames/s with 3 words/s (a BEAT2 speaker's rate)."""
    rate = 100.0
    print("audio min  words   before s   now s   ratio   same spans")
    for minutes in (6.0, 60.0 * hours):
        n = int(minutes * 60 * rate)
        volume = np.random.default_rng(0).random(n)
        words = [Word(text="x", start_s=k / 3.0, end_s=k / 3.0 + 0.25, syllables=1) for k in range(int(minutes * 180))]
        t0 = time.perf_counter()
        old = spans_before(volume, rate, 0.5, n / rate, 0.3, words)
        before = time.perf_counter() - t0
        t0 = time.perf_counter()
        new = silent_spans(volume, rate, 0.5, n / rate, 0.3, words)
        after = time.perf_counter() - t0
        print(f"{minutes:9.0f}  {len(words):5d}   {before:8.2f}   {after:5.2f}   {before / after:5.1f}x   {old == new}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=0.5, help="longest take for the silent-span timing")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        refusal(Path(d))
    spans(args.hours)


if __name__ == "__main__":
    main()
