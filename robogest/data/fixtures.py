"""A tiny synthetic speech-gesture dataset whose motion is a known function of the audio energy.

Tests use it to show that a learned generator really learns: each "word" is a short chirp with a smooth
loudness envelope, and several joints move in proportion to that (smoothed) envelope, so the motion is predictable
from the audio but not constant. Words are written as JSON timings; motion as BVH or SMPL-X ``.npz``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from robogest.errors import InputError
from robogest.motion import rotations as R
from robogest.motion.skeleton import CANONICAL

#: Words spoken in the fixture (one chirp each); "um" exercises the filler vector.
VOCAB = ("hello", "robot", "wave", "big", "small", "um", "there", "now")
#: Canonical joint -> (axis index, rest angle rad, gain rad per unit envelope) of the fixture's motion.
FIXTURE_GESTURE: dict[str, tuple[int, float, float]] = {
    "r_shoulder": (2, -1.1, 0.9),
    "l_shoulder": (2, 1.1, -0.6),
    "r_elbow": (1, 0.2, 0.8),
    "head": (0, 0.0, 0.25),
    "spine1": (1, 0.0, 0.15),
}
_MOTION_FPS = 30.0
_SR = 16000


def _words(duration_s: float, rng: np.random.Generator) -> list[tuple[str, float, float]]:
    """``(word, start_s, end_s)``: phrases of 2-5 words separated by 0.6-1.0 s pauses."""
    out: list[tuple[str, float, float]] = []
    t = 0.3
    while True:
        for _ in range(int(rng.integers(2, 6))):
            d = float(rng.uniform(0.2, 0.45))
            if t + d > duration_s - 0.3:
                return out
            out.append((VOCAB[int(rng.integers(len(VOCAB)))], t, t + d))
            t += d + float(rng.uniform(0.03, 0.12))
        t += float(rng.uniform(0.6, 1.0))


def _envelope(words: list[tuple[str, float, float]], t_s: np.ndarray) -> np.ndarray:
    """Loudness envelope in [0, 1] at times ``t_s``: a Hann bump per word."""
    env = np.zeros_like(t_s)
    for _, s, e in words:
        sel = (t_s >= s) & (t_s < e)
        env[sel] = np.maximum(env[sel], np.sin(np.pi * (t_s[sel] - s) / (e - s)) ** 2)
    return env


def fixture_poses(words: list[tuple[str, float, float]], t_s: np.ndarray) -> np.ndarray:
    """The fixture's ground-truth exponential maps ``(T, J, 3)`` radians at times ``t_s``.

    The envelope is smoothed by a 0.15 s one-pole filter so the motion lags and eases like a gesture.
    """
    env = _envelope(words, t_s)
    smooth = np.zeros_like(env)
    dt = float(t_s[1] - t_s[0]) if t_s.shape[0] > 1 else 1.0 / _MOTION_FPS
    a = np.exp(-dt / 0.15)
    for i in range(1, env.shape[0]):
        smooth[i] = a * smooth[i - 1] + (1.0 - a) * env[i]
    smooth /= max(float(smooth.max()), 1e-9)
    rv = np.zeros((t_s.shape[0], CANONICAL.n_joints, 3))
    for name, (axis, rest, gain) in FIXTURE_GESTURE.items():
        rv[:, CANONICAL.index(name), axis] = rest + gain * smooth
    return rv


def _audio(words: list[tuple[str, float, float]], duration_s: float, rng: np.random.Generator) -> np.ndarray:
    n = round(duration_s * _SR)
    t = np.arange(n) / _SR
    audio = 0.002 * rng.standard_normal(n)  # faint room noise
    for w, s, e in words:
        sel = (t >= s) & (t < e)
        u = (t[sel] - s) / (e - s)  # 0..1 through the word
        f0 = 140.0 + 15.0 * (sum(map(ord, w)) % 7)  # word-dependent pitch, Hz
        phase = 2 * np.pi * (f0 * (t[sel] - s) + 40.0 * (e - s) * u**2)  # upward chirp
        tone = np.sin(phase) + 0.5 * np.sin(2 * phase) + 0.25 * np.sin(3 * phase)
        audio[sel] += 0.3 * np.sin(np.pi * u) ** 2 * tone
    return np.clip(audio, -1.0, 1.0).astype(np.float32)


def _write_npz(path: Path, rv: np.ndarray) -> None:
    from robogest.motion.smplx import SMPLX_INDEX

    poses = np.zeros((rv.shape[0], 55, 3), dtype=np.float32)
    for name, i in SMPLX_INDEX.items():
        poses[:, i] = rv[:, CANONICAL.index(name)]
    trans = np.tile([0.0, 0.9, 0.0], (rv.shape[0], 1)).astype(np.float32)
    np.savez(path, poses=poses.reshape(rv.shape[0], 165), trans=trans, mocap_frame_rate=np.float64(_MOTION_FPS))


def make_fixture_dataset(
    root: str | os.PathLike,
    n_takes: int = 3,
    duration_s: float = 8.0,
    motion_format: str = "bvh",
    layout: str = "pairs",
    seed: int = 0,
) -> Path:
    """Write a synthetic dataset folder and return its path.

    Parameters
    ----------
    root : path-like
        Created if missing.
    n_takes : int
        Recordings ``take_000`` ...
    duration_s : float
        Length of each take, s (audio and motion equally long).
    motion_format : {"bvh", "npz"}
        Canonical-skeleton BVH or SMPL-X parameters.
    layout : {"pairs", "genea", "genea2023", "beat2"}
        Folder layout (see :mod:`robogest.data.datasets`); ``genea`` and ``genea2023`` need BVH, ``beat2`` npz.
    seed : int
        Fixes words, timings and noise.
    """
    import soundfile as sf

    from robogest.motion.bvh import save_bvh
    from robogest.motion.human_motion import HumanMotion

    if motion_format not in ("bvh", "npz"):
        raise InputError(f"motion_format must be 'bvh' or 'npz', got {motion_format!r}")
    dirs = {
        "pairs": ("", "", ""),
        "genea": ("Audio", "Motion", "Transcripts"),
        "genea2023": ("main-agent/wav", "main-agent/bvh", "main-agent/tsv"),
        "beat2": ("wave16k", "smplxflame_30", "textgrid"),
    }
    if layout not in dirs:
        raise InputError(f"layout must be one of {', '.join(dirs)}, got {layout!r}")
    if (layout, motion_format) in (("genea", "npz"), ("genea2023", "npz"), ("beat2", "bvh")):
        raise InputError(f"the {layout} layout uses {'npz' if layout == 'beat2' else 'bvh'} motion")
    root = Path(root)
    a_dir, m_dir, t_dir = (root / d for d in dirs[layout])
    for d in (a_dir, m_dir, t_dir):
        d.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for k in range(n_takes):
        name = f"take_{k:03d}"
        words = _words(duration_s, rng)
        sf.write(a_dir / f"{name}.wav", _audio(words, duration_s, rng), _SR, subtype="PCM_16")
        t_s = np.arange(round(duration_s * _MOTION_FPS)) / _MOTION_FPS
        rv = fixture_poses(words, t_s)  # (T, J, 3)
        if motion_format == "bvh":
            root_pos = np.tile([0.0, 1.0, 0.0], (t_s.shape[0], 1))
            save_bvh(HumanMotion(_MOTION_FPS, R.from_axis_angle(rv), root_pos), m_dir / f"{name}.bvh")
        else:
            _write_npz(m_dir / f"{name}.npz", rv)
        if layout == "beat2":
            _write_textgrid(t_dir / f"{name}.TextGrid", words, duration_s)
        elif layout == "genea2023":  # start<TAB>end<TAB>word, no header
            rows = "".join(f"{s:.3f}\t{e:.3f}\t{w}\n" for w, s, e in words)
            (t_dir / f"{name}.tsv").write_text(rows, encoding="utf-8")
        else:
            doc = {"words": [{"word": w, "start_time": f"{s:.3f}s", "end_time": f"{e:.3f}s"} for w, s, e in words]}
            (t_dir / f"{name}.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    return root


def _write_textgrid(path: Path, words: list[tuple[str, float, float]], duration_s: float) -> None:
    """A minimal long-format Praat TextGrid with one ``words`` tier (pauses as empty intervals)."""
    ivs, t = [], 0.0
    for w, s, e in words:
        if s > t:
            ivs.append((t, s, ""))
        ivs.append((s, e, w))
        t = e
    if t < duration_s:
        ivs.append((t, duration_s, ""))
    lines = [
        'File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0", f"xmax = {duration_s}",
        "tiers? <exists>", "size = 1", "item []:", "    item [1]:", '        class = "IntervalTier"',
        '        name = "words"', "        xmin = 0", f"        xmax = {duration_s}",
        f"        intervals: size = {len(ivs)}",
    ]  # fmt: skip
    for i, (s, e, w) in enumerate(ivs, 1):
        lines += [
            f"        intervals [{i}]:",
            f"            xmin = {s}",
            f"            xmax = {e}",
            f'            text = "{w}"',
        ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
