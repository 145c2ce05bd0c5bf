"""Speech front-end: audio file or text in, words, beats, silent periods and frame features out.

Public API::

    SpeechConfig                       settings (frame rate, beat gaps, thresholds, limits)
    load_speech(audio, transcript)     audio file (+ .txt/.TextGrid/.json/.tsv transcript) -> Speech
    synthesize(text, voice, wpm)       offline eSpeak NG TTS with word timings -> Speech
    synthesize_segments(segments)      the same for text pieces with their own pauses and rates (scripts)
    synthesize_with_stress(text, ...)  the same Speech + eSpeak's stressed-syllable onsets (evaluation only)
    analyze(audio, sr, words, config)  the shared core, mono float32 in -> Speech
    save_features / write_wav / speech_summary
"""

from __future__ import annotations

from robogest.speech.beats import identify_beats
from robogest.speech.config import SpeechConfig
from robogest.speech.core import (
    TextSegment,
    analyze,
    audio_beats,
    load_speech,
    synthesize,
    synthesize_segments,
    synthesize_with_stress,
)
from robogest.speech.export import save_features, speech_summary, write_wav
from robogest.speech.transcript import count_syllables
from robogest.speech.types import FILLER_WORDS, Speech, SpeechFeatures, Word

__all__ = [
    "FILLER_WORDS",
    "Speech",
    "SpeechConfig",
    "SpeechFeatures",
    "TextSegment",
    "Word",
    "analyze",
    "audio_beats",
    "count_syllables",
    "identify_beats",
    "load_speech",
    "save_features",
    "speech_summary",
    "synthesize",
    "synthesize_segments",
    "synthesize_with_stress",
    "write_wav",
]
