"""Data classes every stage after the speech front-end consumes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Word spellings treated as fillers (Gesticulator §4.1 gives them one shared text vector).
FILLER_WORDS = frozenset({"uh", "um", "uhm", "er", "erm", "ah", "eh", "hmm", "mm", "like", "so"})


@dataclass(frozen=True)
class Word:
    """One spoken word with its time span.

    Attributes
    ----------
    text : str
        The word, lower case, punctuation stripped.
    start_s, end_s : float
        Span in seconds from the start of the audio, ``start_s < end_s``.
    syllables : int
        Syllable count (>= 1), used for speaking rate and for spreading untimed text.
    """

    text: str
    start_s: float
    end_s: float
    syllables: int = 1

    @property
    def is_filler(self) -> bool:
        return self.text in FILLER_WORDS


@dataclass(frozen=True)
class SpeechFeatures:
    """Frame-synchronous features; frame ``t`` covers time ``t / fps`` seconds.

    Attributes
    ----------
    fps : float
        Frames per second (20 by default, Gesticulator §4.1).
    mel_db : ndarray [shape=(T, 64)], dB
        Log-power mel spectrogram, window 0.1 s.
    mfcc : ndarray [shape=(T, 37)]
        c0 (log energy), c1..c12, then first and second forward differences of c1..c12 (13 + 12 + 12;
        S2AG §3.1.1 counts 37 values, its "14 + 13 + 13" wording does not add up).
    rms : ndarray [shape=(T,)], linear amplitude
        RMS energy per frame.
    pitch_hz : ndarray [shape=(T,)], Hz
        Fundamental frequency, 0 where unvoiced.
    word_features : ndarray [shape=(T, 5)]
        Gesticulator Table 1: time since word start (s), time to word end (s), word duration (s),
        relative progress in [0, 1], speaking rate (syllables/s). Zero outside words.
    filler : ndarray [shape=(T,)], bool
        Frame lies in a filler word.
    silence : ndarray [shape=(T,)], bool
        Frame lies in a silent period (see :attr:`Speech.silent_spans`).
    """

    fps: float
    mel_db: np.ndarray
    mfcc: np.ndarray
    rms: np.ndarray
    pitch_hz: np.ndarray
    word_features: np.ndarray
    filler: np.ndarray
    silence: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.rms.shape[0])


@dataclass(frozen=True)
class Speech:
    """Audio, words, beats, silent spans and features of one utterance.

    Attributes
    ----------
    audio : ndarray [shape=(N,)], float32 in [-1, 1]
        Mono samples.
    sr : int
        Sample rate, Hz.
    words : tuple of Word
        Time-ordered, possibly empty (audio without transcript).
    beats_s : ndarray [shape=(B,)], seconds
        Beat times (Rhythmic Gesticulator §4.2.1), increasing.
    beat_is_pseudo : ndarray [shape=(B,)], bool
        True where the beat was inserted into a long gap rather than found as an onset.
    silent_spans : tuple of (float, float)
        ``(start_s, end_s)`` spans with no speech, each at least the configured minimum length.
    noise_level : float
        Estimated environmental-noise RMS level Ĩ_a (linear amplitude).
    features : SpeechFeatures
    source : str
        File path or ``"tts:<voice>"``; used in messages and saved trajectories.
    text : str
        The transcript as given, "" if none.
    offset_s : float
        Where this speech starts within the utterance it was cut from (:meth:`crop`), seconds; 0 for a whole
        one. Motion that runs on its own clock (idle sway) uses it so that a cut and the whole agree.
    heard_s : float or None
        For a partial utterance (a live stream's :meth:`SpeechStream.speech`), how much of :attr:`audio` was
        heard, seconds; the zeros after it stand for speech still to come. None: all of it.
    """

    audio: np.ndarray
    sr: int
    words: tuple[Word, ...]
    beats_s: np.ndarray
    beat_is_pseudo: np.ndarray
    silent_spans: tuple[tuple[float, float], ...]
    noise_level: float
    features: SpeechFeatures
    source: str = ""
    text: str = ""
    audio_path: Path | None = field(default=None)
    offset_s: float = 0.0
    heard_s: float | None = None

    @property
    def duration_s(self) -> float:
        return float(self.audio.shape[0]) / float(self.sr)

    @property
    def fps(self) -> float:
        return self.features.fps

    @property
    def n_frames(self) -> int:
        return self.features.n_frames

    def crop(self, start_s: float) -> Speech:
        """The speech from ``start_s`` on, with every time re-based to it (words starting earlier dropped).

        ``start_s`` is snapped to the feature grid (``round(start_s * fps) / fps``) so frame ``t`` of the result is
        frame ``t + k0`` of this one; a streaming planner uses it to keep each replan to a bounded stretch.
        """
        fps = self.features.fps
        k0 = min(max(0, round(start_s * fps)), self.n_frames)
        t0 = k0 / fps
        if k0 == 0:
            return self
        f = self.features
        feats = SpeechFeatures(
            fps, f.mel_db[k0:], f.mfcc[k0:], f.rms[k0:], f.pitch_hz[k0:], f.word_features[k0:], f.filler[k0:],
            f.silence[k0:],
        )  # fmt: skip
        words = tuple(Word(w.text, w.start_s - t0, w.end_s - t0, w.syllables) for w in self.words if w.start_s >= t0)
        keep = self.beats_s >= t0
        spans = tuple((max(a, t0) - t0, b - t0) for a, b in self.silent_spans if b > t0)
        return Speech(
            audio=self.audio[min(round(t0 * self.sr), self.audio.shape[0]) :],
            sr=self.sr,
            words=words,
            beats_s=self.beats_s[keep] - t0,
            beat_is_pseudo=self.beat_is_pseudo[keep],
            silent_spans=spans,
            noise_level=self.noise_level,
            features=feats,
            source=self.source,
            text=" ".join(w.text for w in words) if self.words else "",
            offset_s=self.offset_s + t0,
            heard_s=None if self.heard_s is None else max(0.0, self.heard_s - t0),
        )
