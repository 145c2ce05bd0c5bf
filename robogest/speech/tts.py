"""Offline text-to-speech with eSpeak NG (via ``espeakng-loader``), with word timings from its events.

Each utterance is synthesized in a short-lived child interpreter (:mod:`robogest.speech._espeak_worker`,
stdlib only, ~70 ms including synthesis of a sentence). eSpeak NG keeps synthesis state in C function
statics that no API call resets (pitch-flutter index, gain control), so a second utterance in the same
process differs by a few samples; a fresh process per utterance makes the output a pure function of
text, voice and rate, and keeps eSpeak's process-global state out of ours.

Word timings come from ``espeakEVENT_WORD`` events (``sample`` position, ``text_position``, ``length``);
events pointing into the same characters (a number read as several words) merge into one word.

Phonemes (only on request, :func:`espeak_synthesize_phonemes`) come from ``espeakEVENT_PHONEME`` events
(``espeakINITIALIZE_PHONEME_EVENTS``; the audio is unchanged). eSpeak marks stress on syllabic phonemes with
``'`` (primary: stress levels 4-5 of its 0-5 scale, after its sentence-level demotion of function words) or
``,`` (levels 2-3). Upstream eSpeak NG 1.52 writes phoneme events without stress marks; the build that
``espeakng-loader`` ships adds them (``WritePhMnemonicWithStress``). eSpeak emits the event of a vowel that
follows a liquid or nasal only after the vowel's onset transition, so those events come late
(:data:`LIQUID_NASAL_VOWEL_LAG_S`).
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robogest.errors import InputError, MissingDependencyError

MIN_WPM, MAX_WPM = 80, 450
_WORKER = Path(__file__).with_name("_espeak_worker.py")
_TIMEOUT_S = 120.0
#: How late eSpeak's event of a vowel after a liquid or nasal comes after the vowel's onset, s (it is emitted
#: after the vowel's onset transition). ``benchmarks/diag_tts_stress.py``: the steepest level rise lies this
#: much further before such events than before the other stressed-vowel events, on its 18 calibration
#: sentences (25 ms; 50 ms on its report set, so the value is uncertain by about 25 ms).
LIQUID_NASAL_VOWEL_LAG_S = 0.025
#: eSpeak mnemonics of liquids, glides and nasals (English and the common European voices; a variant suffix
#: after ``/`` is never reported).
_LIQUIDS_NASALS = frozenset({"l", "r", "w", "j", "m", "n", "N", "R", "r-", "l-", "m-", "n-", "J", "n^", "l^", "L"})


@dataclass(frozen=True)
class WordEvent:
    """One word as eSpeak reports it.

    Attributes
    ----------
    start_sample : int
        First sample of the word in the synthesized audio (at eSpeak's rate).
    char_start, char_end : int
        0-based character span of the word in the input text.
    """

    start_sample: int
    char_start: int
    char_end: int


@dataclass(frozen=True)
class PhonemeEvent:
    """One phoneme as eSpeak reports it.

    Attributes
    ----------
    start_sample : int
        Sample of the event in the synthesized audio (at eSpeak's rate).
    char_start : int
        0-based character position of the word the phoneme belongs to.
    name : str
        eSpeak phoneme mnemonic, with its stress mark (``'`` primary, ``,`` secondary) in front when stressed.
    """

    start_sample: int
    char_start: int
    name: str

    @property
    def stress(self) -> int:
        """2 primary, 1 secondary, 0 unstressed or not a syllable."""
        return {"'": 2, ",": 1}.get(self.name[:1], 0)


def lags_onset(previous: str) -> bool:
    """Whether eSpeak emits a vowel's event late because of the phoneme before it (a liquid or nasal mnemonic)."""
    return previous.lstrip("',") in _LIQUIDS_NASALS


def stressed_vowel_onsets(phonemes: list[PhonemeEvent], sr: int) -> np.ndarray:
    """Onsets of the stressed (primary or secondary) syllables among eSpeak's phoneme events, seconds ``(K,)``.

    Stress marks sit only on syllabic phonemes, so every marked event is a stressed syllable's nucleus; events
    after a liquid or nasal are moved :data:`LIQUID_NASAL_VOWEL_LAG_S` earlier (see the module docstring).

    Parameters
    ----------
    phonemes : list of PhonemeEvent
        One utterance's events in audio order (:func:`espeak_synthesize_phonemes`).
    sr : int
        eSpeak's sample rate, Hz.
    """
    out = [
        p.start_sample / sr - (LIQUID_NASAL_VOWEL_LAG_S if k > 0 and lags_onset(phonemes[k - 1].name) else 0.0)
        for k, p in enumerate(phonemes)
        if p.stress
    ]
    return np.maximum(np.sort(np.asarray(out, dtype=np.float64)), 0.0)


def _espeak_paths() -> tuple[str, str]:
    try:
        import espeakng_loader
    except ImportError as exc:
        raise MissingDependencyError("text-to-speech needs eSpeak NG: pip install espeakng-loader") from exc
    return str(espeakng_loader.get_library_path()), str(espeakng_loader.get_data_path())


def espeak_synthesize(
    text: str, voice: str = "en-us", words_per_minute: int = 160
) -> tuple[np.ndarray, int, list[WordEvent]]:
    """Raw eSpeak NG output for one utterance.

    Returns
    -------
    audio : ndarray [shape=(N,)], float32 in [-1, 1]
    sr : int
        eSpeak's sample rate, Hz (22050).
    events : list of WordEvent
        In audio order, number readings merged (see module docstring).
    """
    audio, sr, header = _run_worker(text, voice, words_per_minute, phonemes=False)
    return audio, sr, _word_events(header)


def espeak_synthesize_phonemes(
    text: str, voice: str = "en-us", words_per_minute: int = 160
) -> tuple[np.ndarray, int, list[WordEvent], list[PhonemeEvent]]:
    """:func:`espeak_synthesize` plus eSpeak's phoneme events (same audio, sample for sample).

    Returns
    -------
    audio, sr, events
        As :func:`espeak_synthesize`.
    phonemes : list of PhonemeEvent
        In audio order.

    Raises
    ------
    MissingDependencyError
        The eSpeak NG build writes phoneme events without stress marks although its own transcription of
        the text has some (upstream eSpeak NG 1.52 does; the build ``espeakng-loader`` ships marks them).
    """
    audio, sr, header = _run_worker(text, voice, words_per_minute, phonemes=True)
    phonemes = [PhonemeEvent(int(s), int(c), str(n)) for s, c, n in sorted(header["phonemes"], key=lambda e: e[0])]
    if int(header.get("stress_marks", 0)) > 0 and not any(p.stress for p in phonemes):
        raise MissingDependencyError(
            "tts: this eSpeak NG build reports phonemes without stress marks; stressed vowels need the build "
            "that espeakng-loader ships (0.2.4 tested: pip install 'espeakng-loader>=0.2.4')"
        )
    return audio, sr, _word_events(header), phonemes


def _run_worker(text: str, voice: str, words_per_minute: int, phonemes: bool) -> tuple[np.ndarray, int, dict]:
    """One utterance through the worker: audio, eSpeak's rate (Hz) and the worker's JSON header."""
    if not text.strip():
        raise InputError("tts: the text is empty")
    if not MIN_WPM <= int(words_per_minute) <= MAX_WPM:
        raise InputError(f"tts: words_per_minute must be in [{MIN_WPM}, {MAX_WPM}], got {words_per_minute}")
    lib_path, data_path = _espeak_paths()
    req = {"text": text, "voice": voice, "wpm": int(words_per_minute)} | ({"phonemes": True} if phonemes else {})
    request = json.dumps(req).encode()
    try:
        proc = subprocess.run(
            [sys.executable, "-I", "-S", str(_WORKER), lib_path, data_path],
            input=request,
            capture_output=True,
            timeout=_TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise MissingDependencyError(f"tts: could not run the eSpeak NG worker ({exc})") from exc
    head, _, pcm = proc.stdout.partition(b"\n")
    try:
        header = json.loads(head)
    except json.JSONDecodeError:
        detail = proc.stderr.decode(errors="replace").strip().splitlines()[-1:] or [f"exit code {proc.returncode}"]
        raise MissingDependencyError(f"tts: eSpeak NG failed: {detail[0]}") from None
    if header.get("error") == "voice":
        raise InputError(f"tts: unknown eSpeak NG voice {voice!r} (try 'en-us', 'en', 'en-gb', 'de', 'fr')")
    if header.get("error") == "init":
        raise MissingDependencyError(f"tts: {header.get('detail')}")
    if header.get("error"):
        raise InputError(f"tts: eSpeak NG could not synthesize the text ({header.get('detail')})")
    audio = np.frombuffer(pcm, dtype="<i2", count=int(header["n_samples"])).astype(np.float32) / 32768.0
    return audio, int(header["sr"]), header


def _word_events(header: dict) -> list[WordEvent]:
    merged: list[WordEvent] = []
    for sample, c0, c1 in sorted(header["events"]):
        if merged and c0 < merged[-1].char_end:
            last = merged[-1]
            merged[-1] = WordEvent(last.start_sample, last.char_start, max(last.char_end, c1))
        else:
            merged.append(WordEvent(int(sample), int(c0), int(c1)))
    return merged
