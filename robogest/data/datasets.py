"""Speech-gesture dataset readers: folders in, aligned takes (features + exponential-map poses at 20 fps) out.

Layouts (detected from the folder):

GENEA 2020 / Trinity
    ``Audio/NAME.wav``, ``Motion/NAME.bvh``, optional ``Transcripts/NAME.json`` (word timings).
GENEA 2022 / 2023 (Talking With Hands)
    ``wav/NAME.wav``, ``bvh/NAME.bvh``, optional ``tsv/NAME.tsv`` (``start<TAB>end<TAB>word``); a split folder
    (``trn/``, ``val/``) holding ``main-agent/`` reads the main agent (the interlocutor is not a take).
BEAT2
    ``wave16k/NAME.wav``, ``smplxflame_30/NAME.npz``, optional ``textgrid/NAME.TextGrid``.
Plain folder of pairs
    ``NAME.wav`` + ``NAME.bvh`` or ``NAME.npz`` + optional ``NAME.TextGrid`` / ``NAME.json`` / ``NAME.txt``.

Each take is the speech features and the motion resampled to the feature rate, both aligned at t = 0 and trimmed
to the shorter. Features are cached as one folder of ``.npy`` files per take, keyed by the input files (path, size,
mtime) and the :class:`~robogest.data.features.FeatureConfig`, so a second run reads them instead of recomputing;
they are memory-mapped read-only from there, so memory does not grow with the dataset and processes share them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.data.features import FeatureConfig, motion_to_expmap, speech_inputs, text_encoder_for
from robogest.errors import InputError

if TYPE_CHECKING:
    from robogest.text import TextEncoder

_AUDIO_EXT = (".wav", ".flac", ".ogg", ".mp3")
_MOTION_EXT = (".bvh", ".npz")
_TRANSCRIPT_EXT = (".TextGrid", ".textgrid", ".json", ".tsv", ".csv", ".txt")


@dataclass(frozen=True)
class TakeFiles:
    """Files of one recording."""

    name: str
    audio: Path
    motion: Path
    transcript: Path | None = None


@dataclass(frozen=True)
class Take:
    """One aligned recording.

    Attributes
    ----------
    name : str
    acoustic : ndarray [shape=(T, 69)], float32
        Log-mel dB (64) + Table 1 word timing features (5); a read-only ``np.memmap`` when loaded from the cache.
    text : ndarray [shape=(T, D)], float32
        Per-frame text features.
    poses : ndarray [shape=(T, J * 3)], float32, radians
        Canonical joint rotations as exponential maps.
    fps : float
    audio_path : Path, optional
        The recording, for models that re-analyse time-scaled audio (the Rhythmic Gesticulator's blocks).
    audio_start_frame : int
        Frame of the recording at which this take starts (non-zero for a take cut from a longer one).
    """

    name: str
    acoustic: np.ndarray
    text: np.ndarray
    poses: np.ndarray
    fps: float
    audio_path: Path | None = None
    audio_start_frame: int = 0

    @property
    def n_frames(self) -> int:
        return int(self.poses.shape[0])

    def slice(self, start: int, stop: int, name: str | None = None) -> Take:
        """Frames ``[start, stop)`` as a new take."""
        return Take(
            name or self.name, self.acoustic[start:stop], self.text[start:stop], self.poses[start:stop], self.fps,
            self.audio_path, self.audio_start_frame + start,
        )  # fmt: skip

    def read_audio(self, sr: int) -> np.ndarray:
        """This take's samples ``(N,)`` at ``sr`` Hz, mono, starting at its frame 0 (sample ``t * sr / fps`` is
        frame ``t``).

        Raises
        ------
        InputError
            The take has no recording (``audio_path`` is None) or it cannot be read.
        """
        from robogest.speech.audio import read_audio, resample

        if self.audio_path is None:
            raise InputError(f"take {self.name}: no audio file is known")
        raw, file_sr = read_audio(self.audio_path, math.inf)
        audio = resample(raw, file_sr, sr)
        return audio[round(self.audio_start_frame * sr / self.fps) :]


def _first(stem_dir: Path, name: str, exts: Sequence[str]) -> Path | None:
    for e in exts:
        p = stem_dir / f"{name}{e}"
        if p.is_file():
            return p
    return None


def _layout_dirs(root: Path) -> tuple[Path, Path, Path, tuple[str, ...]]:
    """``(audio, motion, transcripts, motion suffixes)`` of the layout :func:`detect_layout` finds at ``root``."""
    layout = detect_layout(root)
    if layout == "genea":
        return root / "Audio", root / "Motion", root / "Transcripts", (".bvh",)
    if layout == "genea2023":
        agent = root / "main-agent" if (root / "main-agent" / "wav").is_dir() else root
        return agent / "wav", agent / "bvh", agent / "tsv", (".bvh",)
    if layout == "beat2":
        return root / "wave16k", root / "smplxflame_30", root / "textgrid", (".npz",)
    return root, root, root, _MOTION_EXT


def unpaired_files(root: str | os.PathLike) -> list[Path]:
    """Audio files with no motion file of the same name, and motion files with no audio: left out of training
    (a renamed or missing half is usually a mistake worth a warning)."""
    audio_dir, motion_dir, _, motion_ext = _layout_dirs(Path(root))
    audio = {p.stem: p for p in audio_dir.iterdir() if p.suffix.lower() in _AUDIO_EXT}
    motion = {p.stem: p for p in motion_dir.iterdir() if p.suffix.lower() in motion_ext}
    return sorted([p for n, p in audio.items() if n not in motion] + [p for n, p in motion.items() if n not in audio])


def _pair(audio_dir: Path, motion_dir: Path, text_dir: Path | None, motion_ext: Sequence[str]) -> list[TakeFiles]:
    takes = []
    for a in sorted(p for p in audio_dir.iterdir() if p.suffix.lower() in _AUDIO_EXT):
        m = _first(motion_dir, a.stem, motion_ext)
        if m is None:
            continue
        t = _first(text_dir, a.stem, _TRANSCRIPT_EXT) if text_dir is not None and text_dir.is_dir() else None
        takes.append(TakeFiles(a.stem, a, m, t))
    return takes


def detect_layout(root: str | os.PathLike) -> str:
    """``"genea"``, ``"genea2023"``, ``"beat2"`` or ``"pairs"``."""
    root = Path(root)
    if (root / "Audio").is_dir() and (root / "Motion").is_dir():
        return "genea"
    for agent in (root, root / "main-agent"):
        if (agent / "wav").is_dir() and (agent / "bvh").is_dir():
            return "genea2023"
    if (root / "wave16k").is_dir() and (root / "smplxflame_30").is_dir():
        return "beat2"
    return "pairs"


def discover_takes(root: str | os.PathLike) -> list[TakeFiles]:
    """The takes of a dataset folder (any of the three layouts), sorted by name.

    Raises
    ------
    InputError
        Not a folder, or no audio file with a matching motion file.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root}: dataset folder not found")
    layout = detect_layout(root)
    takes = _pair(*_layout_dirs(root))
    if not takes:
        raise InputError(
            f"{root}: no takes found ({layout} layout). Expected GENEA 2020 (Audio/*.wav + Motion/*.bvh), GENEA "
            "2023 (wav/*.wav + bvh/*.bvh [+ tsv/], or main-agent/ holding them), BEAT2 (wave16k/*.wav + "
            "smplxflame_30/*.npz) or pairs (NAME.wav + NAME.bvh|NAME.npz) in one folder."
        )
    return takes


#: BEAT2's official split file at the dataset root: ``id,type`` rows, type ``train``, ``val``, ``test`` (or
#: ``additional``, trained on like ``train``).
SPLIT_FILE = "train_test_split.csv"


def official_split(root: str | os.PathLike) -> dict[str, str] | None:
    """Take name -> ``"train"``, ``"val"`` or ``"test"`` from ``root/train_test_split.csv`` (BEAT2), else None.

    Raises
    ------
    InputError
        The file exists but has no ``id`` and ``type`` columns.
    """
    import csv
    import io

    from robogest.fileio import read_text_capped

    path = Path(root) / SPLIT_FILE
    if not path.is_file():
        return None
    rows = list(csv.DictReader(io.StringIO(read_text_capped(path, what="split file"), newline="")))
    if not rows or not {"id", "type"} <= set(rows[0]):
        raise InputError(f"{path}: expected the columns id,type (BEAT2's official split)")
    kinds = {"train": "train", "additional": "train", "val": "val", "test": "test"}
    return {r["id"].strip(): kinds.get(r["type"].strip().lower(), "test") for r in rows}


_SPEAKER_RE = re.compile(r"^(\d+)_")


def speaker_key(take_name: str) -> str:
    """Speaker of a take from its name: BEAT2's leading speaker number (``"2_scott_0_1_1"`` -> ``"2"``), else
    ``"default"`` (GENEA/Trinity and plain folders hold one speaker)."""
    m = _SPEAKER_RE.match(take_name)
    return m.group(1) if m else "default"


def default_cache_dir() -> Path:
    """``$ROBOGEST_CACHE_DIR`` or ``$XDG_CACHE_HOME/robogest/features`` (``~/.cache`` by default)."""
    if os.environ.get("ROBOGEST_CACHE_DIR"):
        return Path(os.environ["ROBOGEST_CACHE_DIR"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "robogest" / "features"


def cache_key(files: TakeFiles, config: FeatureConfig) -> str:
    """Hash of the files' absolute paths, sizes and mtimes and of the feature config."""
    h = hashlib.sha1(config.key().encode())
    for p in (files.audio, files.motion, files.transcript):
        if p is None:
            h.update(b"-")
            continue
        st = p.stat()
        h.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:24]


#: Arrays of one take in its cache entry, one ``.npy`` each (memory-mapped when read).
_CACHED_ARRAYS = ("acoustic", "text", "poses")


def cache_entry(files: TakeFiles, config: FeatureConfig, cache_dir: str | os.PathLike | None = None) -> Path:
    """Folder of ``files``' cached features: ``acoustic.npy``, ``text.npy``, ``poses.npy`` and ``meta.json``."""
    cdir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return cdir / f"{files.name}-{cache_key(files, config)}"


def _write_entry(entry: Path, take: Take) -> None:
    """Write a take's arrays into a temporary folder beside ``entry`` and rename it into place (atomic: a reader
    sees a complete entry or none; when another process got there first its identical entry is kept)."""
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{entry.name}.", dir=entry.parent))
    try:
        for k in _CACHED_ARRAYS:
            np.save(tmp / f"{k}.npy", np.ascontiguousarray(getattr(take, k), np.float32))
        (tmp / "meta.json").write_text(json.dumps({"fps": take.fps}), encoding="utf-8")
        tmp.chmod(0o755)
        shutil.rmtree(entry, ignore_errors=True)  # an unreadable entry being replaced
        try:
            os.replace(tmp, entry)
        except OSError:
            if not entry.is_dir():  # not a concurrent writer's complete entry: a real failure
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _read_entry(entry: Path, name: str, audio: Path | None) -> Take:
    """A cached take with its arrays memory-mapped read-only (pages shared by every process that maps them).

    Raises
    ------
    OSError, KeyError, ValueError
        Missing or inconsistent entry.
    """
    fps = float(json.loads((entry / "meta.json").read_text(encoding="utf-8"))["fps"])
    a, t, p = (np.load(entry / f"{k}.npy", mmap_mode="r", allow_pickle=False) for k in _CACHED_ARRAYS)
    if not (a.ndim == t.ndim == p.ndim == 2 and a.shape[0] == t.shape[0] == p.shape[0]):
        raise ValueError(f"{entry}: arrays of different lengths")
    return Take(name, a, t, p, fps, audio)


def compute_take(
    files: TakeFiles,
    config: FeatureConfig,
    encoder: TextEncoder | None = None,
    warn: Callable[[str], None] | None = None,
) -> Take:
    """Read and align one take (no cache).

    A recording of any length is accepted (the speech front-end's ``max_duration_s`` guards interactive input,
    not datasets: GENEA 2020 takes are about 10 min). Timed words that cannot be aligned (zero length without
    room, overlapping, beyond the audio) are dropped with one ``warn`` line for the take.
    """
    from robogest.motion import load_motion
    from robogest.speech import load_speech

    skipped: list[str] = []
    speech_config = dataclasses.replace(config.speech_config(), max_duration_s=math.inf)
    speech = load_speech(files.audio, files.transcript, speech_config, skip_bad_words=skipped.append)
    if skipped:
        (warn or _warn)(f"{files.name}: skipped {len(skipped)} malformed word(s); first: {skipped[0]}")
    motion = load_motion(files.motion).resample(config.fps)
    acoustic, text = speech_inputs(speech, config, encoder)  # (T_s, 69), (T_s, D)
    poses = motion_to_expmap(motion)  # (T_m, J * 3)
    n = min(acoustic.shape[0], poses.shape[0])
    if n == 0:
        raise InputError(f"{files.audio}: the take has no frames")
    a_s, m_s = acoustic.shape[0] / config.fps, poses.shape[0] / config.fps
    if abs(a_s - m_s) > max(1.0, 0.1 * max(a_s, m_s)):  # a wrong frame rate or pairing, not a trailing second
        (warn or _warn)(
            f"{files.name}: audio {a_s:.1f} s and motion {m_s:.1f} s differ; trained on the first {n / config.fps:.1f} "
            "s of both: check the motion's frame rate and that the files belong together"
        )
    return Take(files.name, acoustic[:n], text[:n], poses[:n], float(config.fps), files.audio)


def load_take(
    files: TakeFiles,
    config: FeatureConfig,
    cache_dir: str | os.PathLike | None = None,
    encoder: TextEncoder | None = None,
    warn: Callable[[str], None] | None = None,
    build: bool = True,
) -> Take | None:
    """One take, its arrays memory-mapped from the feature cache (``cache_dir=None``: :func:`default_cache_dir`).

    A take not in the cache is computed and written first (``build=False``: None is returned instead, for DDP
    ranks that only map what the builder rank wrote). Memory-mapped, a dataset's features take no memory beyond
    the pages being read, and processes reading the same entry share those pages.
    """
    entry = cache_entry(files, config, cache_dir)
    if entry.is_dir():
        try:
            return _read_entry(entry, files.name, files.audio)
        except (OSError, KeyError, ValueError):
            pass  # unreadable cache entry: recompute and overwrite
    if not build:
        return None
    _write_entry(entry, compute_take(files, config, encoder, warn))
    return _read_entry(entry, files.name, files.audio)


def load_dataset(
    root: str | os.PathLike,
    config: FeatureConfig,
    cache_dir: str | os.PathLike | None = None,
    progress: Callable[[int, int], None] | None = None,
    warn: Callable[[str], None] | None = None,
    build: bool = True,
) -> list[Take]:
    """Every take of ``root``, aligned, cached on disk and memory-mapped from there (:func:`load_take`).

    A take that cannot be read (unreadable file, a transcript that cannot be parsed) is left out with one ``warn``
    line (default: ``warning: ...`` on stderr), so one bad recording never stops a run. With BEAT2's official split
    (:data:`SPLIT_FILE`) the test takes are not loaded. ``build=False`` computes nothing: takes missing from the
    cache are left out silently (under DDP the builder rank has computed, or warned about, every take).

    Raises
    ------
    InputError
        No take of ``root`` could be read (the message carries the first take's reason).
    """
    files = discover_takes(root)
    say = warn or _warn
    lone = unpaired_files(root)
    if lone and build:
        names = ", ".join(p.name for p in lone[:3]) + (f" and {len(lone) - 3} more" if len(lone) > 3 else "")
        say(f"{len(lone)} file(s) without their audio or motion half, left out: {names}")
    split = official_split(root)
    if split is not None:  # the official test takes never train or select a model
        test = [f for f in files if split.get(f.name, "test") == "test"]
        files = [f for f in files if f not in test]
        say(f"{SPLIT_FILE}: official split used, {len(test)} test (or unlisted) take(s) left out")
        if not files:
            raise InputError(f"{Path(root) / SPLIT_FILE}: no take of the folder is listed as train or val")
    encoder = None
    takes, failed = [], []
    for i, f in enumerate(files):
        if progress is not None:
            progress(i, len(files))
        if build and encoder is None and not cache_entry(f, config, cache_dir).is_dir():
            encoder = text_encoder_for(config)  # only load (seconds for MiniLM) when something is not cached
        try:
            take = load_take(f, config, cache_dir, encoder, say, build)
        except InputError as e:
            failed.append(str(e))
            say(f"{f.name}: take skipped ({e})")
            continue
        if take is not None:
            takes.append(take)
        else:
            failed.append(f"{f.name}: not in the feature cache")
    if progress is not None:
        progress(len(files), len(files))
    if not takes:
        raise InputError(f"{root}: no take could be read; first problem: {failed[0]}")
    return takes


def _warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)
