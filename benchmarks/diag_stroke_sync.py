"""Why does the real BEAT2 take score at chance on stroke sync? (a diagnostic, not a test; issue 13 §1)

Prints, for the shared take ``2_scott_0_1_1``:

1. alignment: the lag (within ±20 s) at which jaw-rotation speed best correlates with the audio's RMS
   loudness (the face is captured with the body, so if speech and motion were misaligned it shows here);
2. stroke sync of several principled motion signals, each against librosa's default onsets and against a
   sparser set (``onset_detect`` with ``wait`` = 0.2 s, i.e. at most 5 syllable-like onsets/s, and
   ``delta`` = 0.2): wrist-position speed (what :func:`robogest.eval.beats.stroke_sync` uses) in the world
   and in the chest frame (root and spine motion removed), and the angular speed of the shoulder + elbow
   rotations (no forward kinematics involved);
3. the shifted-motion control for the best of these;
4. a scan of the wrist stroke-sync z over motion offsets of -10..+10 s in 0.1 s steps (a body capture offset
   from the face and audio would show as one offset with a high z).

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/diag_stroke_sync.py``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks
from scipy.spatial.transform import Rotation

from robogest.eval.beats import ONSET_SR, audio_onsets, chance_corrected, stroke_hit_rate, stroke_peaks, stroke_sync
from robogest.motion import load_motion
from robogest.motion import rotations as R
from robogest.speech import load_speech

STEM = Path(__file__).resolve().parents[1].parent / "shared/data/beat2/2_scott_0_1_1"
#: SMPL-X joint indices: jaw; left and right shoulder, elbow.
JAW, ARMS = 22, ((16, 18), (17, 19))


def _z(x: np.ndarray) -> np.ndarray:
    return (x - x.mean()) / (x.std() + 1e-12)


def _angular_peaks(poses: np.ndarray, fps: float) -> np.ndarray:
    """Peaks of summed shoulder + elbow angular speed per arm (rad/s), prominence 1/4 of the 5-95 % range."""
    out = []
    for joints in ARMS:
        w = 0.0
        for j in joints:
            r = Rotation.from_rotvec(poses[:, j])
            s = (r[:-1].inv() * r[1:]).magnitude() * fps
            w = w + np.r_[s, s[-1]]
        v = gaussian_filter1d(w, 0.05 * fps)
        lo, hi = np.percentile(v, [5, 95])
        idx, _ = find_peaks(v, prominence=0.25 * (hi - lo), distance=round(0.2 * fps))
        out.append(idx / fps)
    return np.sort(np.concatenate(out))


def main() -> None:
    import librosa

    m = load_motion(f"{STEM}.npz")
    sp = load_speech(f"{STEM}.wav", f"{STEM}.TextGrid")
    fps, n = m.fps, m.n_frames
    dur, spans = n / fps, list(sp.silent_spans)
    poses = np.load(f"{STEM}.npz")["poses"].astype(np.float64).reshape(n, -1, 3)

    t = np.arange(n) / fps
    rms = librosa.feature.rms(y=sp.audio, frame_length=1024, hop_length=160)[0]
    loud = _z(gaussian_filter1d(np.interp(t, np.arange(rms.size) * 160 / sp.sr, rms), 0.1 * fps))
    jaw = _z(gaussian_filter1d(np.abs(np.gradient(np.linalg.norm(poses[:, JAW], axis=1))), 0.1 * fps))
    lags = np.arange(-round(20 * fps), round(20 * fps) + 1)
    c = np.array([np.mean(jaw * np.roll(loud, k)) for k in lags])
    best = int(np.argmax(c))
    print(f"alignment: jaw speed vs loudness peaks at lag {lags[best] / fps:+.2f} s (r = {c[best]:.2f}, ", end="")
    print(f"r at 0 = {c[lags.size // 2]:.2f}, sd over lags = {c.std():.2f})")

    y = librosa.resample(np.asarray(sp.audio, np.float32), orig_sr=sp.sr, target_sr=ONSET_SR)
    env = librosa.onset.onset_strength(y=y, sr=ONSET_SR)
    wait = round(0.2 * ONSET_SR / 512)
    onsets = {
        "librosa default": audio_onsets(sp.audio, sp.sr),
        "wait 0.2 s, delta 0.2": librosa.onset.onset_detect(
            onset_envelope=env, sr=ONSET_SR, units="time", wait=wait, delta=0.2
        ),
    }
    rot = m.rotations.copy()
    for name in ("pelvis", "spine", "spine1", "spine2"):
        rot[:, m.skeleton.index(name)] = R.IDENTITY
    chest = dataclasses.replace(m, rotations=rot, root_pos_m=np.zeros_like(m.root_pos_m))
    wrists = [m.skeleton.index("l_wrist"), m.skeleton.index("r_wrist")]
    peaks = {
        "wrist position speed (world)": stroke_peaks(m.positions()[:, wrists], fps),
        "wrist position speed (chest frame)": stroke_peaks(chest.positions()[:, wrists], fps),
        "shoulder+elbow angular speed": _angular_peaks(poses, fps),
    }

    def score(p: np.ndarray, on: np.ndarray) -> dict:
        return chance_corrected(lambda a, b: stroke_hit_rate(a, b, spans), p, on, dur)

    for pn, p in peaks.items():
        for on_name, on in onsets.items():
            r = score(p, on)
            print(f"{pn:36s} {p.size:4d} peaks | {on_name:22s} {on.size:4d} onsets ({on.size / dur:.1f}/s): ", end="")
            print(f"hit {r['score']:.2f} chance {r['null_mean']:.2f} z {r['z']:+.2f}")
    p, on = peaks["shoulder+elbow angular speed"], onsets["librosa default"]
    zs = np.array([score(np.sort((p + s) % dur), on)["z"] for s in np.arange(2.0, dur - 2.0, 1.0)])
    print(f"shoulder+elbow, shifted 2..{dur - 2:.0f} s in 1 s steps: |z| median {np.median(np.abs(zs)):.2f}, ", end="")
    print(f"max {np.abs(zs).max():.2f}, share > 1.5: {np.mean(np.abs(zs) > 1.5):.2f}")
    w = m.positions()[:, wrists]
    offs = np.arange(-100, 101) / 10.0
    zo = np.array([stroke_sync(np.roll(w, round(o * fps), axis=0), fps, on, spans, n_shifts=40)["z"] for o in offs])
    top = np.argsort(-zo)[:3]
    best_offsets = ", ".join(f"{offs[i]:+.1f} s z {zo[i]:+.2f}" for i in top)
    print(f"wrist stroke sync over offsets -10..+10 s (201 offsets): best {best_offsets}")


if __name__ == "__main__":
    main()
