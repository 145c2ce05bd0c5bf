"""Do eSpeak's stressed-vowel events sit where the audio has stressed vowels? (a diagnostic, not a test)

For synthesized speech the stroke-sync reference events are eSpeak NG's own phoneme events with its stress
marks (:func:`robogest.speech.synthesize_with_stress`). This checks them against the audio, with the shared
BEAT2 take's forced-aligned stressed vowels (ARPAbet stress 1/2, the events the measure was validated with)
as the yardstick of what real stressed-vowel onsets look like:

- ``loud``: level of [t, t + 60 ms] in dB above the median level of the speech frames;
- ``voiced``: fraction of events whose [t + 5, t + 45] ms is periodic (normalised autocorrelation peak at
  80-400 Hz above 0.5);
- ``rise``: where the steepest level rise within [t - 80, t + 40] ms lies, relative to t (median, ms): 0 when
  the event sits on the vowel's energy onset;
- against unstressed vowels and random times during speech (null), and per-second densities.

eSpeak emits the phoneme event of a vowel that follows a liquid or nasal after the vowel's onset transition;
:data:`robogest.speech.tts.LIQUID_NASAL_VOWEL_LAG_S` corrects for it. That lag is calibrated here on the
CALIBRATION sentences only (how much further before those vowels' raw events the median rise lies than
before the other stressed vowels': 25 ms); the REPORT set is the TTS paragraphs of
``benchmarks/bench_generalize.py`` and ``bench_live.py``, not looked at for it, where the same difference is
50 ms. The rise is a crude onset estimate (5 ms frames; on the BEAT2 take it lies 15 ms before the aligner's
onsets), so the lag is uncertain by about 25 ms.

Measured (this script): stressed events +7.4 / +8.2 dB (calibration / report), 92 / 88 % voiced, 2.1 / 2.0
per second of speech; unstressed vowels +3.3 / +4.5 dB; BEAT2's aligned stressed vowels +4.4 dB, 93 %, 3.1/s.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/diag_tts_stress.py`` (about 10 s).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

BEAT2 = Path(__file__).resolve().parents[1].parent / "shared/data/beat2/2_scott_0_1_1"
HOP_S, WIN_S = 0.005, 0.025

#: Sentences the liquid/nasal lag is calibrated on (nothing else uses them).
CALIBRATION = [
    "Hello, today I am happy.",
    "My mother made lemon marmalade on Monday morning.",
    "The rain in Spain stays mainly in the plain, or so I have been told.",
    "Really? I never knew that the river ran so near the old mill.",
    "We will meet again in the library later, when the lecture is over.",
    "Nobody remembers the name of the man who made the first map of the moon.",
    "Please put the big black bag back in the car before it gets dark.",
    "Could you tell me the way to the station? I think I took a wrong turn.",
    "Seven lovely lilies grew along the narrow lane beside the lake.",
    "Honestly, the best part of the trip was the food, not the museums.",
    "If the weather is fine tomorrow, we could take the boat out to the island.",
    "Learning a new language takes time, patience, and a lot of listening.",
    "Her neighbour's dog barked all night, so nobody in the building could sleep.",
    "I would love to help, but I really need to finish this report by noon.",
    "Remember to water the plants and to lock the door when you leave.",
    "The children laughed when the clown fell off his little yellow bicycle.",
    "Most people underestimate how much energy a long meeting takes.",
    "Turn left at the corner, walk past the bakery, and the museum is right there.",
]


def _levels(audio: np.ndarray, sr: int) -> np.ndarray:
    hop, win = round(HOP_S * sr), round(WIN_S * sr)
    n = max(1, 1 + (len(audio) - win) // hop)
    padded = np.pad(audio, (win // 2, win))  # frame k is centred on k * HOP_S
    frames = np.lib.stride_tricks.sliding_window_view(padded, win)[::hop][:n]
    return 10 * np.log10(np.mean(frames.astype(np.float64) ** 2, axis=1) + 1e-10)


def _periodic(audio: np.ndarray, sr: int, t: float) -> bool:
    seg = audio[round((t + 0.005) * sr) : round((t + 0.045) * sr)].astype(np.float64)
    if seg.size < round(0.03 * sr) or not np.any(seg):
        return False
    seg = seg - seg.mean()
    ac = np.correlate(seg, seg, "full")[seg.size - 1 :]
    lo, hi = round(sr / 400), min(round(sr / 80), seg.size - 1)
    return bool(ac[lo:hi].max() / (ac[0] + 1e-12) > 0.5)


def event_values(audio: np.ndarray, sr: int, times: np.ndarray, speech_frames: np.ndarray) -> dict:
    """Per event at ``times`` (s): ``loud`` (dB above the clip's speech median), ``voiced`` (bool), ``rise`` (ms)."""
    db = _levels(audio, sr)
    ref = float(np.median(db[speech_frames[: db.size]]))
    rise_curve = np.convolve(np.gradient(db), np.ones(3) / 3, "same")
    loud, voiced, rise = [], [], []
    for t in np.asarray(times, dtype=np.float64):
        k = round(t / HOP_S)
        if k >= db.size - 12:
            continue
        loud.append(db[k : k + 12].mean() - ref)
        voiced.append(_periodic(audio, sr, t))
        k0, k1 = max(0, k - 16), min(db.size, k + 9)
        rise.append((k0 + int(np.argmax(rise_curve[k0:k1])) - k) * HOP_S * 1000)
    return {"loud": np.array(loud), "voiced": np.array(voiced, dtype=bool), "rise": np.array(rise)}


def summary(values: list[dict]) -> dict:
    """Pooled over clips: ``n``, median ``loud``, fraction ``voiced``, median ``rise`` and its quartiles."""
    v = {k: np.concatenate([x[k] for x in values]) if values else np.zeros(0) for k in ("loud", "voiced", "rise")}
    return {
        "n": int(v["loud"].size),
        "loud": float(np.median(v["loud"])),
        "voiced": float(np.mean(v["voiced"])),
        "rise": float(np.median(v["rise"])),
        "rise_iqr": tuple(np.percentile(v["rise"], [25, 75]).round()),
    }


def audio_stats(audio: np.ndarray, sr: int, times: np.ndarray, speech_frames: np.ndarray) -> dict:
    return summary([event_values(audio, sr, times, speech_frames)])


def _speech_frames(speech, n_frames: int) -> np.ndarray:
    t = np.arange(n_frames) * HOP_S
    ok = np.ones(n_frames, dtype=bool)
    for a, b in speech.silent_spans:
        ok &= ~((t >= a) & (t < b))
    return ok


def _row(name: str, st: dict, density: float | None = None) -> str:
    d = f"{density:5.2f}/s" if density is not None else " " * 7
    return (f"  {name:<44} n={st['n']:4d} {d}  loud {st['loud']:+5.1f} dB  voiced {st['voiced']:.2f}  "
            f"rise {st['rise']:+4.0f} ms (IQR {st['rise_iqr'][0]:+.0f}..{st['rise_iqr'][1]:+.0f})")  # fmt: skip


def _speech_time(speech) -> float:
    return speech.duration_s - sum(b - a for a, b in speech.silent_spans)


def beat2_reference() -> None:
    from praatio import textgrid

    from robogest.speech import load_speech

    if not BEAT2.with_suffix(".wav").is_file():
        print("BEAT2 take not found; no real-speech yardstick")
        return
    sp = load_speech(BEAT2.with_suffix(".wav"), BEAT2.with_suffix(".TextGrid"))
    tg = textgrid.openTextgrid(str(BEAT2.with_suffix(".TextGrid")), includeEmptyIntervals=False)
    phones = [(float(e.start), str(e.label).upper()) for e in tg.getTier("phones").entries]
    stressed = np.array([t for t, lab in phones if lab[-1:] in "12" and lab[:-1].isalpha()])
    unstressed = np.array([t for t, lab in phones if lab[-1:] == "0"])
    frames = _speech_frames(sp, len(_levels(sp.audio, sp.sr)))
    rng = np.random.default_rng(0)
    rand = rng.uniform(0, sp.duration_s, 4000)
    rand = rand[frames[np.minimum((rand / HOP_S).astype(int), frames.size - 1)]][:400]
    secs = _speech_time(sp)
    print(f"BEAT2 scott take (real speech, MFA alignment, {secs:.0f} s of speech): the yardstick")
    print(_row("stressed vowels (ARPAbet 1/2)", audio_stats(sp.audio, sp.sr, stressed, frames), stressed.size / secs))
    print(
        _row("unstressed vowels (ARPAbet 0)", audio_stats(sp.audio, sp.sr, unstressed, frames), unstressed.size / secs)
    )
    print(_row("random times in speech", audio_stats(sp.audio, sp.sr, rand, frames)))


def is_vowel(name: str) -> bool:
    """eSpeak vowel mnemonics start with one of these (English and the common European voices)."""
    return name.lstrip("',")[:1] in set("aAeEiIoOuUV03@y")


def tts_events(text: str, voice: str = "en-us", wpm: int = 160) -> tuple:
    """Speech, raw stressed-vowel events split by preceding phoneme, unstressed vowels, corrected events."""
    from robogest.speech import synthesize_with_stress
    from robogest.speech.tts import espeak_synthesize_phonemes, lags_onset

    # single chunk only (no ellipsis), so eSpeak's sample positions are the Speech's timeline
    sp, corrected = synthesize_with_stress(text, voice=voice, words_per_minute=wpm)
    _, esr, _, ph = espeak_synthesize_phonemes(text, voice, wpm)
    after_ln, other, unstressed = [], [], []
    for prev, p in zip([None, *ph[:-1]], ph, strict=True):
        if not is_vowel(p.name):
            continue
        t = p.start_sample / esr
        if p.stress == 0:
            unstressed.append(t)
        elif lags_onset(prev.name if prev else ""):
            after_ln.append(t)
        else:
            other.append(t)
    return sp, np.array(after_ln), np.array(other), np.array(unstressed), corrected


def tts_set(title: str, items: list[tuple[str, str, int]]) -> None:
    groups: dict[str, list] = {k: [] for k in ("after_ln", "other", "unstressed", "corrected")}
    secs = 0.0
    per_clip = []
    for text, voice, wpm in items:
        sp, after_ln, other, unstressed, corrected = tts_events(text, voice, wpm)
        frames = _speech_frames(sp, len(_levels(sp.audio, sp.sr)))
        for k, ev in zip(groups, (after_ln, other, unstressed, corrected), strict=True):
            groups[k].append((sp, ev, frames))
        secs += _speech_time(sp)
        per_clip.append(corrected.size / _speech_time(sp))

    def pooled(k: str) -> dict:
        return summary([event_values(sp.audio, sp.sr, ev, fr) for sp, ev, fr in groups[k] if ev.size])

    n = {k: sum(ev.size for _, ev, _ in groups[k]) for k in groups}
    print(f"{title} ({len(items)} clips, {secs:.0f} s of speech; events pooled)")
    print(_row("stressed, after liquid/nasal, raw event", pooled("after_ln"), n["after_ln"] / secs))
    print(_row("stressed, other, raw event", pooled("other"), n["other"] / secs))
    print(_row("stressed vowels as returned (lag corrected)", pooled("corrected"), n["corrected"] / secs))
    print(_row("unstressed vowels", pooled("unstressed"), n["unstressed"] / secs))
    print(f"  stressed vowels per second of speech, per clip: {' '.join(f'{d:.2f}' for d in per_clip)}")
    lag = pooled("other")["rise"] - pooled("after_ln")["rise"]
    print(f"  lag of events after a liquid/nasal behind the others (difference of median rises): {lag:.0f} ms")


def main() -> int:
    from bench_generalize import TTS
    from bench_live import PARAGRAPH, TEXT

    from robogest.speech.core import PAUSE_MARK

    beat2_reference()
    tts_set("CALIBRATION sentences (the liquid/nasal lag is set from these)", [(t, "en-us", 160) for t in CALIBRATION])
    report = [(c, voice, wpm) for _, voice, wpm, text in TTS for c in PAUSE_MARK.split(text) if c.strip()]
    report += [(TEXT, "en-us", 160)] + [(c, "en-us", 160) for c in PAUSE_MARK.split(PARAGRAPH) if c.strip()]
    tts_set("REPORT: bench_generalize + bench_live TTS texts, ellipsis chunks as clips", report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
