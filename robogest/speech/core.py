"""The front-end's entry points: audio file or text in, :class:`Speech` out."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robogest.errors import InputError
from robogest.speech.audio import read_audio, resample
from robogest.speech.beats import detect_onsets, gate_onsets, identify_beats
from robogest.speech.config import SpeechConfig
from robogest.speech.features import acoustic_features, speech_features
from robogest.speech.silence import (
    active_regions,
    activity_threshold,
    estimate_noise_level,
    find_runs,
    fine_volume,
    silent_spans,
)
from robogest.speech.transcript import count_syllables, normalize_word, read_transcript, spread_words, validate_words
from robogest.speech.tts import espeak_synthesize, espeak_synthesize_phonemes, stressed_vowel_onsets
from robogest.speech.types import Speech, Word

_DEFAULT = SpeechConfig()


def _check_audio(audio: np.ndarray, sr: int, config: SpeechConfig, source: str) -> np.ndarray:
    a = np.asarray(audio)
    if a.ndim != 1:
        raise InputError(f"{source}: expected mono audio of shape (N,), got {a.shape}; mix it down first")
    if a.shape[0] == 0:
        raise InputError(f"{source}: audio contains no samples")
    if sr <= 0:
        raise InputError(f"{source}: invalid sample rate {sr}")
    if a.shape[0] / sr > config.max_duration_s:
        raise InputError(
            f"{source}: {a.shape[0] / sr:.1f} s is longer than the maximum {config.max_duration_s:.1f} s; "
            "cut it into utterances of at most that length (from Python, SpeechConfig.max_duration_s raises it)"
        )
    a = a.astype(np.float32, copy=False)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{source}: audio contains NaN or infinite samples")
    return a


def analyze(
    audio: np.ndarray,
    sr: int,
    words: Sequence[Word] = (),
    config: SpeechConfig = _DEFAULT,
    source: str = "",
    text: str = "",
) -> Speech:
    """Features, beats and silent periods of mono audio with optional timed words.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32 in [-1, 1]
        Mono samples at ``sr``; resampled once to ``config.sr``, which is also the stored rate.
    sr : int
        Sample rate of ``audio``, Hz.
    words : sequence of Word
        Timed words (any order); validated against the audio's length.
    config : SpeechConfig
    source, text : str
        Copied into the result; ``source`` names the input in error messages.

    Returns
    -------
    Speech
        ``audio_path`` is None; :func:`load_speech` fills it in.

    Raises
    ------
    InputError
        Empty, too long or non-finite audio; words that cannot be aligned.
    """
    source = source or "audio"
    a = _check_audio(audio, sr, config, source)
    a = resample(a, sr, config.sr)
    sr = config.sr
    duration = a.shape[0] / sr
    ws = validate_words(words, duration, source) if words else ()

    volume, vrate, noise, thresh = _volume(a, sr, config)
    spans = silent_spans(volume, vrate, thresh, duration, config.min_silence_s, ws)
    beats, pseudo = _beats(a, sr, volume, vrate, thresh, config)

    acoustic = acoustic_features(a, sr, config, thresh)
    n_frames = config.n_frames(a.shape[0], sr)
    feats = speech_features(acoustic, ws, spans, n_frames, config.fps)
    return Speech(
        audio=a,
        sr=sr,
        words=ws,
        beats_s=beats,
        beat_is_pseudo=pseudo,
        silent_spans=spans,
        noise_level=noise,
        features=feats,
        source=source,
        text=text,
    )


def _volume(a: np.ndarray, sr: int, config: SpeechConfig) -> tuple[np.ndarray, float, float, float]:
    """Fine volume track, its rate, the noise level and the activity threshold of samples ``a`` at ``sr``."""
    volume, vrate = fine_volume(a, sr, config)
    noise = estimate_noise_level(volume, config)
    return volume, vrate, noise, activity_threshold(noise, config)


def _beats(
    a: np.ndarray, sr: int, volume: np.ndarray, vrate: float, thresh: float, config: SpeechConfig
) -> tuple[np.ndarray, np.ndarray]:
    onsets = gate_onsets(detect_onsets(a, sr, round(sr / vrate)), volume, vrate, thresh)
    return identify_beats(
        onsets, volume, thresh, vrate, config.min_beat_gap_s, config.max_beat_gap_s, duration_s=a.shape[0] / sr
    )


def audio_beats(audio: np.ndarray, sr: int, config: SpeechConfig = _DEFAULT) -> tuple[np.ndarray, np.ndarray]:
    """The beats :func:`analyze` puts in ``Speech.beats_s`` (and their pseudo flags), without the other features:
    for recordings whose features are cached (learned-model training takes), so they are cut by the same rule.

    Parameters
    ----------
    audio : ndarray [shape=(N,)], float32
        Mono samples at ``sr`` Hz (any length: no ``max_duration_s`` check).

    Returns
    -------
    beats_s : ndarray [shape=(B,)], seconds
    is_pseudo : ndarray [shape=(B,)], bool
    """
    a = resample(np.asarray(audio, np.float32), sr, config.sr)
    if a.shape[0] == 0:
        return np.zeros(0), np.zeros(0, bool)
    volume, vrate, _, thresh = _volume(a, config.sr, config)
    return _beats(a, config.sr, volume, vrate, thresh, config)


def load_speech(
    audio_path: str | Path,
    transcript_path: str | Path | None = None,
    config: SpeechConfig = _DEFAULT,
    skip_bad_words: Callable[[str], None] | None = None,
) -> Speech:
    """Load an audio file (WAV/FLAC/OGG/MP3, any rate, stereo mixed down) with an optional transcript.

    Parameters
    ----------
    audio_path : str or Path
    transcript_path : str or Path, optional
        ``.txt`` (untimed, spread over the voiced regions by syllables), ``.TextGrid`` (``words`` tier),
        ``.json`` or ``.tsv``/``.csv`` word timings; see :mod:`robogest.speech.transcript`.
    config : SpeechConfig
    skip_bad_words : callable, optional
        Receives the message of each timed word that cannot be aligned, which is then dropped (datasets); without
        it such a word is an :class:`InputError`.

    Raises
    ------
    InputError
        One message naming the file and the problem.
    """
    path = Path(audio_path)
    raw, file_sr = read_audio(path, config.max_duration_s)
    source = str(path)
    words: tuple[Word, ...] = ()
    text = ""
    if transcript_path is not None:
        tr = read_transcript(transcript_path, raw.shape[0] / file_sr)
        text = tr.text
        where = f"transcript {transcript_path} for {path}"
        if tr.timed:
            words = validate_words(tr.words, raw.shape[0] / file_sr, where, skip=skip_bad_words)
        else:
            a = resample(raw, file_sr, config.sr)
            volume, vrate = fine_volume(a, config.sr, config)
            thresh = activity_threshold(estimate_noise_level(volume, config), config)
            regions = active_regions(volume, vrate, thresh, a.shape[0] / config.sr, config.min_silence_s)
            words = spread_words(tr.tokens, regions, where)
            raw, file_sr = a, config.sr  # already resampled: analyze() will not do it again
    speech = analyze(raw, file_sr, words, config, source=source, text=text)
    return dataclasses.replace(speech, audio_path=path)


def _trim_word(start: int, end: int, loud: np.ndarray, hop: int, guard: int = 4) -> tuple[int, int]:
    """Shrink a sample span to its loud part (eSpeak's spans run up to the next word, pauses included).

    ``loud`` is the fine activity mask, frame ``i`` centred at sample ``i * hop``. Loud runs that start in
    the last ``guard`` frames are the next word's onset leaking in through the analysis window and are
    ignored.
    """
    i0, i1 = start // hop, min(loud.shape[0], -(-end // hop))
    runs = find_runs(loud[i0:i1])
    runs = [r for r in runs if r[0] < (i1 - i0) - guard] or runs
    if not runs:
        return start, end
    new_start = max(start, (i0 + runs[0][0]) * hop - hop // 2)
    new_end = min(end, (i0 + runs[-1][1]) * hop + hop // 2)
    return (new_start, new_end) if new_end > new_start else (start, end)


#: "..." or "…" in text to speak marks a pause of ``pause_s`` seconds.
PAUSE_MARK = re.compile(r"\.\.\.+|…")


def synthesize(
    text: str,
    voice: str = "en-us",
    words_per_minute: int = 160,
    config: SpeechConfig = _DEFAULT,
    pause_s: float = 1.2,
) -> Speech:
    """Speak ``text`` offline with eSpeak NG and analyse it; word timings come from eSpeak's word events.

    A word runs from its event to the next word's event (or the end of the audio), trimmed to the frames
    that are louder than the activity threshold, so pauses at punctuation are not part of a word.
    An ellipsis (``...`` or ``…``) inserts a pause of ``pause_s`` seconds: eSpeak's own pauses at
    punctuation are too short (< 0.5 s) to count as silent periods. Deterministic: the same text, voice
    and rate give the same samples.

    Parameters
    ----------
    text : str
        Plain text (no SSML).
    voice : str
        eSpeak NG voice name, e.g. ``"en-us"``.
    words_per_minute : int
        Speaking rate, 80-450.
    config : SpeechConfig
    pause_s : float
        Length of the pause an ellipsis makes, seconds.

    Raises
    ------
    InputError
        Empty text, unknown voice, rate out of range, or text without speakable words.
    MissingDependencyError
        eSpeak NG (``espeakng-loader``) is not installed.
    """
    return _synthesize(text, voice, words_per_minute, config, pause_s, stress=False)[0]


def synthesize_with_stress(
    text: str,
    voice: str = "en-us",
    words_per_minute: int = 160,
    config: SpeechConfig = _DEFAULT,
    pause_s: float = 1.2,
) -> tuple[Speech, np.ndarray]:
    """:func:`synthesize` and the onsets of the stressed syllables eSpeak spoke, for evaluation only.

    The onsets are the stroke-sync measure's reference events for synthesized speech
    (:func:`robogest.eval.beats.stroke_sync_events`), the TTS counterpart of a forced alignment's
    stressed-vowel onsets. They are returned beside the Speech, not in it, so no generator can place strokes on
    them. The Speech is the one :func:`synthesize` returns (same samples: eSpeak's phoneme events do not
    change its audio). See :func:`robogest.speech.tts.stressed_vowel_onsets` for how they are derived.

    Returns
    -------
    speech : Speech
    stressed_vowels_s : ndarray [shape=(K,)], seconds
        Increasing onsets on the Speech's timeline (ellipsis pauses included).
    """
    return _synthesize(text, voice, words_per_minute, config, pause_s, stress=True)


@dataclass(frozen=True)
class TextSegment:
    """A stretch of text spoken at one rate after a pause: the pieces of an annotated script
    (:func:`synthesize_segments`).

    Attributes
    ----------
    text : str
        Plain text ("" for a pause alone); an ellipsis inside still pauses ``pause_s``.
    words_per_minute : int or None
        Its rate (80-450); None: the call's.
    pause_before_s : float
        Silence inserted before it, seconds (0-10).
    resume_after : (segment, char, seconds) or None
        The pause lasts at least until ``seconds`` after the start of the word at character ``char`` of segment
        ``segment`` (an earlier one): speech waiting for something started at that word.
    """

    text: str
    words_per_minute: int | None = None
    pause_before_s: float = 0.0
    resume_after: tuple[int, int, float] | None = None


def synthesize_segments(
    segments: Sequence[TextSegment],
    voice: str = "en-us",
    words_per_minute: int = 160,
    config: SpeechConfig = _DEFAULT,
    pause_s: float = 1.2,
    text: str = "",
) -> tuple[Speech, tuple[tuple[float, float], ...]]:
    """:func:`synthesize` of several segments, each at its own rate after its own pause, as one utterance.

    Each text piece is one eSpeak NG call (as around an ellipsis); the pauses are digital silence.

    Returns
    -------
    speech : Speech
        ``text`` (default: the segments' texts joined) is its :attr:`Speech.text`.
    pauses_s : tuple of (float, float)
        One per segment: where the silence inserted before it lies, seconds (``(t, t)`` when none).
    """
    for seg in segments:
        if not 0 <= seg.pause_before_s <= 10:
            raise InputError(f"tts: a pause must be within [0, 10] s, got {seg.pause_before_s}")
    joined = text or " ".join(s.text for s in segments if s.text.strip())
    speech, _, pauses = _synthesize_pieces(list(segments), voice, words_per_minute, config, pause_s, False, joined)
    return speech, pauses


def _pieces(segments: list[TextSegment], wpm: int, pause_s: float) -> list[tuple[str, int, float, int, int, bool]]:
    """The eSpeak calls: ``(text, wpm, pause before s, segment, char offset in it, first of its segment)``; a
    segment's text is cut at each ellipsis (``pause_s`` between the pieces); one with nothing to say is a pause
    alone ("")."""
    out: list[tuple[str, int, float, int, int, bool]] = []
    for k, seg in enumerate(segments):
        rate = seg.words_per_minute or wpm
        starts = [0, *(m.end() for m in PAUSE_MARK.finditer(seg.text))]
        ends = [*(m.start() for m in PAUSE_MARK.finditer(seg.text)), len(seg.text)]
        kept = [(a, seg.text[a:b]) for a, b in zip(starts, ends, strict=True)]
        kept = [(a, c) for a, c in kept if any(ch.isalnum() for ch in c)]
        if not kept:
            out.append(("", rate, seg.pause_before_s, k, 0, True))
        for i, (a, chunk) in enumerate(kept):
            out.append((chunk, rate, seg.pause_before_s if i == 0 else pause_s, k, a, i == 0))
    return out


def _synthesize(
    text: str, voice: str, words_per_minute: int, config: SpeechConfig, pause_s: float, stress: bool
) -> tuple[Speech, np.ndarray]:
    """:func:`synthesize`; with ``stress`` also eSpeak's stressed-syllable onsets (s), else an empty array."""
    if not isinstance(text, str) or not text.strip():
        raise InputError("tts: the text is empty")
    speech, stressed, _ = _synthesize_pieces(
        [TextSegment(text)], voice, words_per_minute, config, pause_s, stress, text
    )
    return speech, stressed


def _synthesize_pieces(
    segments: list[TextSegment],
    voice: str,
    words_per_minute: int,
    config: SpeechConfig,
    pause_s: float,
    stress: bool,
    text: str,
) -> tuple[Speech, np.ndarray, tuple[tuple[float, float], ...]]:
    """The segments spoken one eSpeak call per piece (:func:`_pieces`) and put end to end with their pauses."""
    if not 0 <= pause_s <= 10:
        raise InputError(f"tts: pause_s must be within [0, 10] s, got {pause_s}")
    source = f"tts:{voice}"
    pieces = _pieces(segments, words_per_minute, pause_s)
    if not any(p[0] for p in pieces):
        raise InputError(f"{source}: the text has no speakable words: {text[:40]!r}")
    spoken = _speak_pieces(segments, pieces, voice, stress)
    raw = np.concatenate(spoken.parts)
    if raw.shape[0] == 0:
        raise InputError(f"{source}: eSpeak NG produced no audio for {text[:40]!r}")
    a = _check_audio(raw, spoken.sr, config, source)
    a = resample(a, spoken.sr, config.sr)
    words = _timed_words(a, spoken.words, config.sr / spoken.sr, config)
    if not words:
        raise InputError(f"{source}: the text has no speakable words: {text[:40]!r}")
    speech = analyze(a, config.sr, words, config, source=source, text=text)
    stressed = np.concatenate(spoken.stressed_s) if spoken.stressed_s else np.zeros(0)
    return speech, stressed, tuple(spoken.pauses)


@dataclass
class _Spoken:
    """eSpeak's output for a list of pieces, end to end at its own rate ``sr`` (before resampling)."""

    sr: int
    parts: list[np.ndarray]  # float32 audio and zero pauses, in order
    words: list[tuple[int, str]]  # (start sample, word text as written)
    stressed_s: list[np.ndarray]  # stressed-vowel onsets of each spoken piece, seconds
    pauses: list[tuple[float, float]]  # (start_s, end_s) of the pause before each segment; (0, 0) if none


def _speak_pieces(
    segments: list[TextSegment], pieces: list[tuple[str, int, float, int, int, bool]], voice: str, stress: bool
) -> _Spoken:
    """One eSpeak call per piece, each after its pause; a segment that resumes after an earlier word
    (``resume_after``) waits until that word started plus its hold, which needs the word's sample (``anchors``)."""
    out = _Spoken(sr=22050, parts=[], words=[], stressed_s=[], pauses=[(0.0, 0.0)] * len(segments))
    anchors: dict[tuple[int, int], int] = {}  # (segment, char) of each word -> its start sample
    offset, wait_s = 0, 0.0  # eSpeak's rate is known from its first call (22050 for every voice)
    for chunk, rate, before_s, k, at, first in pieces:
        resume = segments[k].resume_after
        if first and resume is not None:
            before_s = _resume_pause_s(resume, anchors, before_s, offset, wait_s, out.sr)
        wait_s += before_s
        if not chunk:
            continue
        if stress:
            raw, out.sr, events, phonemes = espeak_synthesize_phonemes(chunk, voice, rate)
        else:
            raw, out.sr, events = espeak_synthesize(chunk, voice, rate)
        if wait_s > 0 and (out.parts or first):
            out.parts.append(np.zeros(round(wait_s * out.sr), dtype=np.float32))
            if first:
                out.pauses[k] = (offset / out.sr, (offset + out.parts[-1].shape[0]) / out.sr)
            offset += out.parts[-1].shape[0]
        wait_s = 0.0
        if stress:
            out.stressed_s.append(offset / out.sr + stressed_vowel_onsets(phonemes, out.sr))
        out.words += [(offset + e.start_sample, chunk[e.char_start : e.char_end]) for e in events]
        anchors.update({(k, at + e.char_start): offset + e.start_sample for e in events})
        out.parts.append(raw)
        offset += raw.shape[0]
    if wait_s > 0:  # a pause after the last words
        out.parts.append(np.zeros(round(wait_s * out.sr), dtype=np.float32))
        out.pauses[pieces[-1][3]] = (offset / out.sr, (offset + out.parts[-1].shape[0]) / out.sr)
    return out


def _resume_pause_s(
    resume_after: tuple[int, int, float],
    anchors: dict[tuple[int, int], int],
    before_s: float,
    offset: int,
    wait_s: float,
    sr: int,
) -> float:
    """A segment's pause lengthened so that it ends ``hold_s`` after the start of the word it resumes after
    (:attr:`TextSegment.resume_after`); unchanged when that word was not spoken. ``offset`` is the samples spoken
    so far and ``wait_s`` the silence already owed before the segment."""
    seg, char, hold_s = resume_after
    t0 = min((s for (sg, c), s in anchors.items() if sg == seg and c >= char), default=None)
    if t0 is None:
        return before_s
    return max(before_s, (t0 - offset) / sr - wait_s + hold_s)


def _timed_words(a: np.ndarray, spoken: list[tuple[int, str]], scale: float, config: SpeechConfig) -> list[Word]:
    """The words eSpeak reported, their starts moved to ``a``'s rate (``scale``: new rate / eSpeak's) and trimmed
    to the loud part of the audio; each ends where the next starts, so a word that got no audio is dropped."""
    volume, vrate = fine_volume(a, config.sr, config)
    loud = volume > activity_threshold(estimate_noise_level(volume, config), config)
    hop = round(config.sr / vrate)
    n = a.shape[0]
    words: list[Word] = []
    starts = [min(n, round(sample * scale)) for sample, _ in spoken]
    for k, (_, raw_word) in enumerate(spoken):
        token = normalize_word(raw_word).replace(" ", "")
        end = starts[k + 1] if k + 1 < len(spoken) else n
        if not token or end <= starts[k]:
            continue
        s0, s1 = _trim_word(starts[k], end, loud, hop)
        if words and s0 / config.sr < words[-1].end_s:
            s0 = round(words[-1].end_s * config.sr)
        if s1 <= s0:
            continue
        words.append(Word(token, s0 / config.sr, s1 / config.sr, count_syllables(token)))
    return words
