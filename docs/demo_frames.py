"""Make the README picture ``docs/demo_frames.png`` from ``out/demo.mp4`` (``make demo``).

Usage: ``python docs/demo_frames.py [out/demo.mp4] [docs/demo_frames.png]``. The times are those of the demo
sentence with the default generator and seed: two beat strokes (wrist-speed peaks of the command trajectory at
0.94 s and 2.02 s), the rest pose held in the first pause (the trajectory sits exactly at rest from 5.06 s to
5.64 s) and the next gesture (a peak at 6.0 s).
"""

from __future__ import annotations

import sys
from pathlib import Path

import av
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

FRAMES = ((0.94, "stroke"), (2.02, "stroke"), (5.4, "pause, at rest"), (6.0, "next gesture"))


def main(video: str = "out/demo.mp4", out: str = "docs/demo_frames.png") -> Path:
    wanted = sorted(FRAMES)
    images = {}
    with av.open(video) as c:
        for frame in c.decode(video=0):
            t = float(frame.pts * frame.time_base)
            for when, _ in wanted:
                if when not in images and t >= when - 1e-6:
                    images[when] = frame.to_ndarray(format="rgb24")
            if len(images) == len(wanted):
                break
    missing = [w for w, _ in wanted if w not in images]
    if missing:
        raise SystemExit(f"{video} is shorter than {max(missing)} s; run `make demo` first")
    fig, axes = plt.subplots(1, len(wanted), figsize=(4 * len(wanted), 2.6))
    for ax, (when, label) in zip(axes, wanted, strict=True):
        ax.imshow(images[when])
        ax.set_title(f"{when:g} s: {label}", fontsize=10)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    return Path(out)


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
