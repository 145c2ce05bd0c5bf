"""Train/validation split by take, normalisation statistics and fixed-length training windows."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

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
        a = np.concatenate([t.acoustic for t in takes]).astype(np.float64)  # (sum T, 69)
        p = np.concatenate([t.poses for t in takes]).astype(np.float64)  # (sum T, J * 3)

        def std(x: np.ndarray) -> np.ndarray:
            s = x.std(axis=0)
            return np.where(s < MIN_STD, 1.0, s).astype(np.float32)

        return cls(a.mean(axis=0).astype(np.float32), std(a), p.mean(axis=0).astype(np.float32), std(p))

    def acoustic(self, x: np.ndarray) -> np.ndarray:
        return ((x - self.acoustic_mean) / self.acoustic_std).astype(np.float32)

    def pose(self, x: np.ndarray) -> np.ndarray:
        return ((x - self.pose_mean) / self.pose_std).astype(np.float32)

    def pose_inverse(self, x: np.ndarray) -> np.ndarray:
        return (x * self.pose_std + self.pose_mean).astype(np.float32)

    def to_dict(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k)) for k in ("acoustic_mean", "acoustic_std", "pose_mean", "pose_std")}

    @classmethod
    def from_dict(cls, d: dict) -> Normalization:
        return cls(**{k: np.asarray(v, dtype=np.float32) for k, v in d.items()})


def make_windows(
    takes: Sequence[Take], norm: Normalization, length: int, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut normalised takes into overlapping windows of ``length`` frames (read lazily, :func:`slice_windows`).

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
    return slice_windows(per_take, length, stride, d_in, d_out)


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

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        """All windows in memory (small sets, tests)."""
        out = self[:]
        return out if dtype is None else out.astype(dtype)

    def __getitem__(self, index) -> np.ndarray:
        index, rest = (index[0], index[1:]) if isinstance(index, tuple) else (index, ())
        starts = self.starts[index]
        rows = np.asarray(starts)[..., None] + np.arange(self.length)  # (..., length)
        out = np.asarray(self.frames[rows], np.float32).reshape(*np.shape(starts), *self.item_shape)
        return out[(..., *rest)] if rest and np.ndim(starts) == 0 else out[(slice(None), *rest)] if rest else out


class _Spill:
    """Frame arrays ``(T_i, d)`` appended to an anonymous temporary file and mapped back read-only ``(sum T_i, d)``
    (the file disappears with the mapping)."""

    def __init__(self, d: int) -> None:
        import tempfile

        self.d, self.n = d, 0
        self.file = tempfile.TemporaryFile()  # noqa: SIM115  (lives as long as the memory map)

    def append(self, x: np.ndarray) -> None:
        self.file.write(np.ascontiguousarray(x, np.float32).tobytes())
        self.n += x.shape[0]

    def mapped(self) -> np.ndarray:
        self.file.flush()
        if self.n == 0:
            self.file.close()
            return np.zeros((0, self.d), np.float32)
        return np.memmap(self.file, dtype=np.float32, mode="r", shape=(self.n, self.d))


def slice_windows(
    per_take: Iterable[tuple], length: int, stride: int, d_in: int, d_out: int,
    x_shape: tuple[int, ...] | None = None, y_shape: tuple[int, ...] | None = None,
) -> tuple[LazyWindows, LazyWindows, np.ndarray]:  # fmt: skip
    """Overlapping windows of ``length`` frames every ``stride`` frames from per-take model arrays, held on disk.

    The takes' frames stream to memory-mapped temporary files one take at a time (:class:`LazyWindows`), so only
    one take's arrays are in memory at once, whatever the dataset's size.

    Parameters
    ----------
    per_take : iterable of (take index, x [shape=(T, d_in)], y [shape=(T, d_out)][, stride])
        Takes shorter than ``length`` give no window; an optional fourth item overrides ``stride`` for that take.
    x_shape, y_shape : tuple of int, optional
        Shape of one window as returned (default ``(length, d_in)`` / ``(length, d_out)``).

    Returns
    -------
    x : LazyWindows [shape=(N, *x_shape)], float32
    y : LazyWindows [shape=(N, *y_shape)], float32
    take_index : ndarray [shape=(N,)], int
    """
    if stride < 1 or length < 1:
        raise InputError("window length and stride must be >= 1")
    starts, idx = [], []
    fx, fy = _Spill(d_in), _Spill(d_out)
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
    xshape = x_shape or (length, d_in)
    yshape = y_shape or (length, d_out)
    s = np.asarray(starts, np.int64)
    return (
        LazyWindows(fx.mapped(), s, length, xshape),
        LazyWindows(fy.mapped(), s, length, yshape),
        np.asarray(idx, int),
    )
