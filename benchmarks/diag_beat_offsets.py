"""How far after the default generator's acoustic beats do the stroke-sync reference events lie? (a diagnostic)

For every clip of ``bench_generalize.py`` (both BEAT2 halves and the synthesized clips), each stressed-vowel
onset (forced alignment for BEAT2, eSpeak NG's stressed syllables for TTS) is paired with its nearest acoustic
beat (:meth:`RhythmGenerator.beats`); pairs more than 0.15 s apart count as unmatched. It prints the beat rate,
the matched share and the median and quartiles of ``event - beat``: a stroke led by ``stroke_lead_s`` scores a
hit on its beat's event when ``-stroke_lead_s <= event - beat <= 0.2 - stroke_lead_s``.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/diag_beat_offsets.py`` (about 15 s).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_generalize as bg

MATCH_S = 0.15


def main() -> int:
    from robogest.generators import make_generator

    clips, _ = bg.beat2_clips()
    if not clips:
        print(f"{bg.BEAT2}.* not found")
        return 0
    gen = make_generator("rhythm", fps=bg.MOCAP_FPS)
    print(f"{'clip':30s} beats/s  matched  event-beat median (IQR), ms")
    for c in clips + bg.tts_clips():
        beats = gen.beats(c.speech).t_s
        ev = c.stressed_vowels_s
        d = ev[:, None] - beats[None]  # (E, B) s
        off = d[np.arange(len(ev)), np.argmin(np.abs(d), axis=1)]
        near = off[np.abs(off) < MATCH_S] * 1000
        q1, med, q3 = np.percentile(near, [25, 50, 75])
        rate = len(beats) / c.speech.duration_s
        print(f"{c.name:30s} {rate:7.2f} {near.size / len(ev):8.2f}  {med:+4.0f} ({q1:+.0f}..{q3:+.0f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
