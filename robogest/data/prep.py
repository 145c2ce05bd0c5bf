"""Train/validation split by take, normalisation statistics and fixed-length training windows."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import EllipsisType

import numpy as np
import numpy.typing as npt

from robogest.data.datasets import Take
from robogest.errors import InputError

#: A standard deviation below this is treated as a constant dimension (divided by 1, not by ~0).
MIN_STD = 1e-4


def split_takes(
    takes: Sequence[Take], val_fraction: float = 0.1, seed: int = 0, official: dict[str, str] | None = None
) -> tuple[list[Take], list[Take]]:
    """Split by take so no recording is in both sets.

    ``official`` (:func:`robogest.data.datasets.official_split`, BEAT2) decides when given: its ``val`` takes
    validate, the rest train, and ``val_fraction`` is not used.

    Takes are ordered by a hash of ``(seed, name)`` (stable however the folder is listed) and the first
    ``round(val_fraction * n)`` (at least one when there are two or more takes) go to validation. A dataset of a
    single take is split in time instead: its last ``val_fraction`` becomes the validation take.

    Returns
    -------
    train, val : list of Take
    """
    if not takes:
        raise InputError("no takes to split")
    if official is not None:
        val = [t for t in takes if official.get(t.name) == "val"]
        return [t for t in takes if official.get(t.name) != "val"], val
    if not 0.0 <= val_fraction < 1.0:
        raise InputError(f"val_fraction must be in [0, 1), got {val_fraction}")
    if val_fraction == 0.0:
        return list(takes), []
    if len(takes) == 1:
        t = takes[0]
        cut = round(t.n_frames * (1.0 - val_fraction))
        return [t.slice(0, cut, f"{t.name}[train]")], [t.slice(cut, t.n_frames, f"{t.name}[val]")]
    order = sorted(takes, key=lambda t: hashlib.sha1(f"{seed}:{t.name}".encode()).hexdigest())
    n_val = max(1, round(val_fraction * len(takes)))
    val = sorted(order[:n_val], key=lambda t: t.name)
    train = sorted(order[n_val:], key=lambda t: t.name)
    return train, val


def moments(chunks: Iterable[np.ndarray], min_std: float = MIN_STD) -> tuple[np.ndarray, np.ndarray]:
    """Per-column mean and standard deviation of the rows of all ``chunks`` together, one chunk in memory at a time
    (Chan et al.'s pairwise update in float64), so a dataset's statistics need no copy of the dataset.

    Parameters
    ----------
    chunks : iterable of ndarray [shape=(T_i, d)]
        E.g. each take's (memory-mapped) features.
    min_std : float
        A standard deviation below this is returned as 1 (a constant column is divided by 1, not by ~0).

    Returns
    -------
    mean : ndarray [shape=(d,)], float64
    std : ndarray [shape=(d,)], float32
        Population standard deviation (``ddof=0``, as ``np.std``).
    """
    n = 0
    mean: np.ndarray | None = None  # (d,) of the rows so far
    m2 = np.zeros(0)  # (d,) sum of squared deviations, set with mean
    for c in chunks:
        x = np.asarray(c, np.float64)  # (T_i, d)
        if x.shape[0] == 0:
            continue
        nb, mb = x.shape[0], x.mean(axis=0)
        m2b = ((x - mb) ** 2).sum(axis=0)
        if mean is None:
            n, mean, m2 = nb, mb, m2b
            continue
        delta, tot = mb - mean, n + nb
        mean = mean + delta * (nb / tot)
        m2 = m2 + m2b + delta**2 * (n * nb / tot)
        n = tot
    if mean is None:
        raise InputError("no frames to compute statistics from")
    std = np.sqrt(m2 / n)
    return mean, np.where(std < min_std, 1.0, std).astype(np.float32)


@dataclass(frozen=True)
class Normalization:
    """Per-dimension mean/std of the acoustic inputs and of the poses, from the training takes.

    Text features are not normalised: the silence vector must stay at -15 (§3.2).

    Attributes
    ----------
    acoustic_mean, acoustic_std : ndarray [shape=(69,)], float32
    pose_mean, pose_std : ndarray [shape=(J * 3,)], float32, radians
    """

    acoustic_mean: np.ndarray
    acoustic_std: np.ndarray
    pose_mean: np.ndarray
    pose_std: np.ndarray

    @classmethod
    def fit(cls, takes: Sequence[Take]) -> Normalization:
        """Statistics of all frames of ``takes``, one take in memory at a time (:func:`moments`)."""
        a_mean, a_std = moments(t.acoustic for t in takes)
        p_mean, p_std = moments(t.poses for t in takes)
        return cls(a_mean.astype(np.float32), a_std, p_mean.astype(np.float32), p_std)

    def acoustic(self, x: np.ndarray) -> np.ndarray:
        return np.asarray((x - self.acoustic_mean) / self.acoustic_std, dtype=np.float32)

    def pose(self, x: np.ndarray) -> np.ndarray:
        return np.asarray((x - self.pose_mean) / self.pose_std, dtype=np.float32)

    def pose_inverse(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x * self.pose_std + self.pose_mean, dtype=np.float32)

    def to_dict(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k)) for k in ("acoustic_mean", "acoustic_std", "pose_mean", "pose_std")}

    @classmethod
    def from_dict(cls, d: dict) -> Normalization:
        return cls(**{k: np.asarray(v, dtype=np.float32) for k, v in d.items()})


def make_windows(
    takes: Sequence[Take], norm: Normalization, length: int, stride: int, store: str | os.PathLike | None = None
) -> tuple[LazyWindows, LazyWindows, np.ndarray]:
    """Cut normalised takes into overlapping windows of ``length`` frames (read lazily, :func:`slice_windows`;
    ``store`` as there).

    Returns
    -------
    speech : LazyWindows [shape=(N, length, 69 + D)], float32
        Normalised acoustic features then raw text features.
    poses : LazyWindows [shape=(N, length, J * 3)], float32
        Normalised poses.
    take_index : ndarray [shape=(N,)], int
        Which take each window comes from.
    """
    per_take = (
        (i, np.concatenate([norm.acoustic(t.acoustic), t.text], axis=1), norm.pose(t.poses))  # (T, 69 + D), (T, P)
        for i, t in enumerate(takes)
        if t.n_frames >= length
    )
    d_in = takes[0].acoustic.shape[1] + takes[0].text.shape[1] if takes else 0
    d_out = takes[0].poses.shape[1] if takes else 0
    return slice_windows(per_take, length, stride, d_in, d_out, store=store)


#: An index into windows or into one window's axes: an int, a slice, or an index array.
_Index = int | slice | np.ndarray | Sequence[int]


class LazyWindows:
    """Overlapping windows read on demand from frames in a memory-mapped file, so the training set's memory does
    not grow with the dataset (the windows overlap: stored whole they would take ``length / stride`` times the
    frames' size).

    Indexing with an int, a slice or an index array returns a float32 ndarray ``(B, *shape[1:])`` (a copy).

    Parameters
    ----------
    frames : ndarray [shape=(F, d)]
        All takes' frames end to end (a read-only ``np.memmap``).
    starts : ndarray [shape=(N,)], int
        First frame of each window.
    length : int
        Frames per window.
    item_shape : tuple of int
        Shape of one window (``(length, d)``, or a reshape of it with as many values).
    """

    def __init__(self, frames: np.ndarray, starts: np.ndarray, length: int, item_shape: tuple[int, ...]) -> None:
        self.frames, self.starts, self.length, self.item_shape = (
            frames,
            np.asarray(starts, np.int64),
            length,
            item_shape,
        )

    @property
    def shape(self) -> tuple[int, ...]:
        return (int(self.starts.shape[0]), *self.item_shape)

    def __len__(self) -> int:
        return int(self.starts.shape[0])

    def __array__(self, dtype: npt.DTypeLike | None = None, copy: bool | None = None) -> np.ndarray:
        """All windows in memory (small sets, tests)."""
        out = self[:]
        return out if dtype is None else out.astype(dtype)

    def __getitem__(self, index: _Index | tuple[_Index, ...]) -> np.ndarray:
        window, rest = (index[0], index[1:]) if isinstance(index, tuple) else (index, ())
        starts = self.starts[window]
        rows = np.asarray(starts)[..., None] + np.arange(self.length)  # (..., length)
        out = np.asarray(self.frames[rows], np.float32).reshape(*np.shape(starts), *self.item_shape)
        if not rest:
            return out
        lead: EllipsisType | slice = ... if np.ndim(starts) == 0 else slice(None)
        key = (lead, *rest)  # the window axis, then the item axes
        picked: np.ndarray = out[key]
        return picked


class _Spill:
    """Frame arrays ``(T_i, d)`` appended to a file and mapped back read-only ``(sum T_i, d)``: an anonymous
    temporary file (gone with the mapping), or ``path`` when other processes map the same frames."""

    def __init__(self, d: int, path: Path | None = None) -> None:
        import tempfile

        self.d, self.n = d, 0
        self.file = tempfile.TemporaryFile() if path is None else open(path, "wb")  # noqa: SIM115  (lives on)

    def append(self, x: np.ndarray) -> None:
        self.file.write(np.ascontiguousarray(x, np.float32).tobytes())
        self.n += x.shape[0]

    def mapped(self) -> np.ndarray:
        self.file.flush()
        if self.n == 0:
            self.file.close()
            return np.zeros((0, self.d), np.float32)
        return np.memmap(self.file, dtype=np.float32, mode="r", shape=(self.n, self.d))

    def close(self) -> None:
        self.file.close()


def slice_windows(
    per_take: Iterable[tuple], length: int, stride: int, d_in: int, d_out: int,
    x_shape: tuple[int, ...] | None = None, y_shape: tuple[int, ...] | None = None,
    store: str | os.PathLike | None = None,
) -> tuple[LazyWindows, LazyWindows, np.ndarray]:  # fmt: skip
    """Overlapping windows of ``length`` frames every ``stride`` frames from per-take model arrays, held on disk.

    The takes' frames stream to memory-mapped files one take at a time (:class:`LazyWindows`), so only one take's
    arrays are in memory at once, whatever the dataset's size.

    Parameters
    ----------
    per_take : iterable of (take index, x [shape=(T, d_in)], y [shape=(T, d_out)][, stride])
        Takes shorter than ``length`` give no window; an optional fourth item overrides ``stride`` for that take.
        Consumed lazily: not at all when ``store`` already holds the windows.
    x_shape, y_shape : tuple of int, optional
        Shape of one window as returned (default ``(length, d_in)`` / ``(length, d_out)``).
    store : path-like, optional
        Folder for the frame files, so several processes (DDP ranks) map one copy: when it exists its windows are
        mapped and ``per_take`` is not read; otherwise they are written there (complete or not at all). Default:
        anonymous temporary files private to this process.

    Returns
    -------
    x : LazyWindows [shape=(N, *x_shape)], float32
    y : LazyWindows [shape=(N, *y_shape)], float32
    take_index : ndarray [shape=(N,)], int
    """
    if stride < 1 or length < 1:
        raise InputError("window length and stride must be >= 1")
    xshape = x_shape or (length, d_in)
    yshape = y_shape or (length, d_out)
    store_dir = None if store is None else Path(store)
    if store_dir is not None and store_dir.is_dir():
        return _open_store(store_dir, length, d_in, d_out, xshape, yshape)
    tmp = None
    if store_dir is not None:
        import tempfile

        store_dir.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{store_dir.name}.", dir=store_dir.parent))
    try:
        starts, idx = [], []
        fx, fy = _Spill(d_in, tmp and tmp / "x.f32"), _Spill(d_out, tmp and tmp / "y.f32")
        for item in per_take:
            i, x, y = item[:3]
            step = int(item[3]) if len(item) > 3 else stride
            if step < 1:
                raise InputError("window stride must be >= 1")
            for s in range(0, x.shape[0] - length + 1, step):
                starts.append(fx.n + s)
                idx.append(i)
            fx.append(x)
            fy.append(y)
        window_starts = np.asarray(starts, np.int64)
        if tmp is not None and store_dir is not None:
            fx.close()
            fy.close()
            np.save(tmp / "starts.npy", window_starts)
            np.save(tmp / "take_index.npy", np.asarray(idx, np.int64))
            (tmp / "meta.json").write_text(json.dumps({"frames": fx.n, "length": length, "d": [d_in, d_out]}))
            os.replace(tmp, store_dir)  # complete, or (on any error above) absent
            return _open_store(store_dir, length, d_in, d_out, xshape, yshape)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return (
        LazyWindows(fx.mapped(), window_starts, length, xshape),
        LazyWindows(fy.mapped(), window_starts, length, yshape),
        np.asarray(idx, int),
    )


def _open_store(
    store: Path, length: int, d_in: int, d_out: int, xshape: tuple[int, ...], yshape: tuple[int, ...]
) -> tuple[LazyWindows, LazyWindows, np.ndarray]:
    """Map the windows :func:`slice_windows` wrote into ``store``."""
    meta = json.loads((store / "meta.json").read_text())
    if meta["length"] != length or meta["d"] != [d_in, d_out]:
        raise InputError(f"{store}: windows of another shape ({meta}); remove the folder")
    n = int(meta["frames"])

    def frames(name: str, d: int) -> np.ndarray:
        return np.memmap(store / name, np.float32, "r", shape=(n, d)) if n else np.zeros((0, d), np.float32)

    s = np.load(store / "starts.npy", mmap_mode="r")
    return (
        LazyWindows(frames("x.f32", d_in), s, length, xshape),
        LazyWindows(frames("y.f32", d_out), s, length, yshape),
        np.load(store / "take_index.npy"),
    )
