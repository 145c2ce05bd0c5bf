"""A take's beats and time-scaled audio blocks, kept across training runs in the feature cache folder.

Cutting a recording at its beats and re-analysing every clip's time-scaled audio (:func:`.blocks.tsm_mel_blocks`)
is the slow part of preparing the rhythmic model's windows: far slower than real time on one core. Both depend on
the recording and a few config fields only, not on the split, the normalisation or the model's widths, so they are
computed once per take and reused by every later run (and every rank) with the same ``--cache-dir``.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from robogest.data.datasets import Take
from robogest.errors import InputError
from robogest.fileio import atomic_path
from robogest.generators.learned.rhythmic.blocks import clip_bounds, tsm_mel_blocks
from robogest.generators.learned.rhythmic.config import RhythmicConfig

#: Bumped whenever the beat rule or the time-scaling changes what an entry holds (old entries are then ignored).
CACHE_VERSION = 1
#: Sub-folder of the cache folder.
FOLDER = "rhythmic-blocks"


def block_cache_key(take: Take, c: RhythmicConfig) -> str:
    """Hex digest of everything the beats and the time-scaled blocks depend on: the recording's bytes, where the
    take starts in it and how long it is, the config's rate, beat and mel fields, and :data:`CACHE_VERSION`."""
    fields = {
        "version": CACHE_VERSION, "n_frames": len(take.acoustic), "take_fps": float(take.fps),
        "audio_start_frame": float(take.audio_start_frame), "audio_sr": c.audio_sr, "fps": c.fps,
        "min_beat_gap_s": c.min_beat_gap_s, "max_beat_gap_s": c.max_beat_gap_s, "n_mels": c.n_mels,
        "mel_window_s": c.mel_window_s, "audio_tsm": bool(c.audio_tsm),
    }  # fmt: skip
    if take.audio_path is None:
        raise InputError(f"take {take.name}: no recording, so no beats or time-scaled blocks to cache")
    h = hashlib.blake2b(json.dumps(fields, sort_keys=True).encode(), digest_size=20)
    with open(take.audio_path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def take_rhythm_blocks(
    take: Take, c: RhythmicConfig, cache_dir: str | os.PathLike | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Beats ``(B,)`` s of a take's recording and, with ``c.audio_tsm``, its time-scaled log-mel blocks
    ``(C, K, n_mels)`` dB before standardisation (else None), read from ``cache_dir`` or computed and stored there
    (``cache_dir=None``: computed, not stored). The take must have a recording (``audio_path``)."""
    from robogest.generators.learned.rhythmic.take import take_beats

    entry = None
    if cache_dir is not None:
        entry = Path(cache_dir) / FOLDER / f"{block_cache_key(take, c)}.npz"
        if entry.is_file():
            with np.load(entry) as z:
                return z["beats_s"], (z["tsm_db"] if c.audio_tsm else None)
    audio = take.read_audio(c.audio_sr)
    beats = take_beats(audio, c)
    tsm = None
    if c.audio_tsm:
        bounds = clip_bounds(np.asarray(beats, np.float64), len(take.acoustic), c.fps)  # as take_rhythm
        tsm = tsm_mel_blocks(audio, c.audio_sr, bounds, c.fps, c.block, c.n_mels, c.mel_window_s)
    if entry is not None:
        entry.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, Any] = {"beats_s": np.asarray(beats)} | ({"tsm_db": tsm} if tsm is not None else {})
        with atomic_path(entry) as tmp, open(tmp, "wb") as f:  # complete or absent, whatever the other ranks do
            np.savez(f, **arrays)
    return beats, tsm
