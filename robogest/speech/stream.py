"""Streaming speech front-end: PCM chunks in, beats, silent periods and features out while speech arrives.

The batch front-end (:func:`robogest.speech.core.analyze`) sees a whole utterance; a voice agent hands
over 10-100 ms chunks. :class:`SpeechStream` keeps the audio received so far and, every
``update_s`` of new audio, re-runs the batch functions on it:

* the fine volume track, noise level and activity threshold (:mod:`robogest.speech.silence`) over
  everything received (an O(N) cumulative sum), so "loud" means what it means offline once a pause
  has been heard;
* onset detection (:func:`~robogest.speech.beats.detect_onsets`) over the last ``window_s`` only, so
  the cost per update is fixed;
* the beat rule (:func:`~robogest.speech.beats.identify_beats`) and silent spans over the whole
  timeline received so far;
* acoustic features (:func:`~robogest.speech.features.acoustic_features`) over the last window (RMS and
  pitch; mel and MFCC only with ``spectral=True``).

Results older than the look-ahead ``lookahead_s`` (L) are *committed*: never revised afterwards.
Newer ones are provisional. A consumer that plays speech delayed by L therefore always knows the
beats of the next L seconds, which is what lets strokes land on beats.

L = 0.25 s, the most issue 16 allows, chosen by measurement (``benchmarks/bench_live.py``): the first motion
follows the first chunk by L (p95 163 ms at 0.15 s, so about 0.26 s here; target 0.3 s), and stroke timing
needs the planner to hear ahead of the player: a stroke's preparation starts well before its beat. Streamed
in real time, the questions clip's stroke-sync z is -0.53 at 0.15 s, 0.82 at 0.25 s and 2.09 at 0.5 s of audio
ahead, against 2.08 offline (10 seeds); a voice agent that delivers audio at 2x real time gets 1.75-2.27.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from robogest.errors import InputError
from robogest.speech.beats import gate_onsets, identify_beats, onset_envelope_peaks
from robogest.speech.config import SpeechConfig
from robogest.speech.features import acoustic_features, mel_hop_win, speech_features
from robogest.speech.silence import activity_threshold, estimate_noise_level, fine_volume, silent_spans
from robogest.speech.transcript import count_syllables, normalize_word
from robogest.speech.types import Speech, Word

#: Look-ahead L, seconds: how far the front-end's committed results trail the newest audio.
DEFAULT_LOOKAHEAD_S = 0.25
#: Onsets and features within this of a window edge are not trusted (analysis windows, peak picking).
_EDGE_S = 0.12


def pcm_to_float(chunk: np.ndarray | bytes, dtype: str = "int16") -> np.ndarray:
    """Mono PCM (int16 or float32 samples, or their raw little-endian bytes) as float32 in [-1, 1].

    Raises
    ------
    InputError
        Not mono, an unknown sample type, or non-finite samples.
    """
    if isinstance(chunk, bytes | bytearray | memoryview):
        if dtype not in ("int16", "float32"):
            raise InputError(f"stream: PCM sample type {dtype!r} is not supported; use int16 or float32")
        chunk = np.frombuffer(bytes(chunk), dtype="<i2" if dtype == "int16" else "<f4")
    a = np.asarray(chunk)
    if a.ndim != 1:
        raise InputError(f"stream: expected mono PCM of shape (N,), got {a.shape}; mix it down first")
    if a.dtype == np.int16:
        return a.astype(np.float32) / 32768.0
    if a.dtype.kind != "f":
        raise InputError(f"stream: PCM must be int16 or float32, got {a.dtype}")
    a = a.astype(np.float32, copy=False)
    if not np.all(np.isfinite(a)):
        raise InputError("stream: PCM chunk contains NaN or infinite samples")
    return a


def parse_word(w: tuple[str, float, float] | Word, after_s: float = -math.inf) -> Word:
    """A streamed word ``(text, start_s, end_s)`` (seconds from the utterance start) as a :class:`Word` (a Word is
    taken as it is), starting no earlier than ``after_s`` (the previous word's start).

    Raises
    ------
    InputError
        Not a (text, start, end) triple, no text left after normalising, not ``0 <= start_s < end_s``, or out of
        time order.
    """
    if isinstance(w, Word):
        word = w
    else:
        try:
            if not isinstance(w, (tuple, list)) or len(w) != 3:
                raise TypeError
            text, t0, t1 = str(w[0]), float(w[1]), float(w[2])
        except (TypeError, ValueError, IndexError):
            raise InputError(f"stream: a word must be (text, start_s, end_s), got {w!r}") from None
        token = normalize_word(text).replace(" ", "")
        if not token or not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0 or t0 < 0:
            raise InputError(f"stream: word {w!r} needs text and 0 <= start_s < end_s")
        word = Word(token, t0, t1, count_syllables(token))
    if word.start_s < after_s:
        raise InputError(f"stream: word {w!r} starts before the previous word; give words in time order")
    return word


class SpeechStream:
    """Online beats, silent spans and features of speech that arrives in chunks.

    Parameters
    ----------
    sample_rate : int
        Rate of the fed chunks, Hz (resampled to ``config.sr`` with a streaming soxr resampler).
    lookahead_s : float
        L, seconds (at most 0.25): results older than ``received_s - L`` are final.
    config : SpeechConfig
    window_s : float
        Audio re-analysed per update for onsets and acoustic features, seconds.
    update_s : float
        New audio between two updates, seconds.
    spectral : bool
        Also compute the mel spectrogram and MFCC (only learned generators use them, and those are batch-only;
        off by default, they stay zero).
    predict_beats : bool
        In the pad of :meth:`speech` (speech not heard yet), continue the beats at the recent pace.
    """

    def __init__(
        self,
        sample_rate: int,
        lookahead_s: float = DEFAULT_LOOKAHEAD_S,
        config: SpeechConfig | None = None,
        window_s: float = 1.0,
        update_s: float = 0.1,
        spectral: bool = False,
        predict_beats: bool = True,
    ) -> None:
        if not 0.0 < lookahead_s <= 0.25:
            raise InputError(f"stream: look-ahead {lookahead_s} s must lie in (0, 0.25]")
        if not 8000 <= int(sample_rate) <= 192000:
            raise InputError(f"stream: sample rate {sample_rate} Hz must lie in [8000, 192000]")
        self.config = config or SpeechConfig()
        self.in_sr = int(sample_rate)
        self.sr = self.config.sr
        self.lookahead_s = float(lookahead_s)
        self.window_s = float(window_s)
        self.update_s = float(update_s)
        self.spectral = spectral
        self.predict_beats = predict_beats
        self._resampler = None
        if self.in_sr != self.sr:
            import soxr

            self._resampler = soxr.ResampleStream(self.in_sr, self.sr, 1, dtype="float32", quality="HQ")
        self._chunks: list[np.ndarray] = []
        self._audio = np.zeros(0, np.float32)
        self._analysed_n = 0
        self.closed = False
        self.words: list[Word] = []
        # committed results
        self._onsets: list[float] = []  # committed onsets (< _onset_commit_s)
        self._onset_commit_s = 0.0
        self._env_max = 0.0  # running maximum of the onset envelope (offline: the utterance's maximum)
        self._beats: list[float] = []
        self._pseudo: list[bool] = []
        self.beat_commit_s = 0.0
        hop, _ = mel_hop_win(self.sr, self.config.fps, self.config.mel_window_s)
        self._feat_hop = hop
        self._feat: dict[str, list[np.ndarray]] = {"mel_db": [], "mfcc": [], "rms": [], "pitch_hz": []}
        self._feat_n = 0  # committed feature frames
        # provisional view of the newest update
        self._prov_beats = np.zeros(0)
        self._prov_pseudo = np.zeros(0, bool)
        self._spans: tuple[tuple[float, float], ...] = ()
        self._noise = self.config.noise_floor
        self._prov_feat: dict[str, np.ndarray] = {}

    # --- input ----------------------------------------------------------------------------
    @property
    def received_s(self) -> float:
        """Seconds of speech received (at the internal rate)."""
        return self._n / self.sr

    @property
    def _n(self) -> int:
        return int(self._audio.shape[0]) + sum(int(c.shape[0]) for c in self._chunks)

    def feed(self, chunk: np.ndarray | bytes, words: Sequence[tuple[str, float, float] | Word] | None = None) -> bool:
        """Append a chunk (mono int16/float32 at ``sample_rate``) and optional words ``(text, start_s, end_s)``
        (or :class:`Word`).

        Returns True when an update ran (new committed beats/spans/features may exist).
        """
        if self.closed:
            raise InputError("stream: feed() after close(); open a new stream for the next utterance")
        a = pcm_to_float(chunk)
        if self._resampler is not None:
            a = self._resampler.resample_chunk(a, last=False)
        if a.size:
            self._chunks.append(np.asarray(a, np.float32))
        if self._n / self.sr > self.config.max_duration_s:
            raise InputError(f"stream: longer than the maximum {self.config.max_duration_s:.0f} s of one utterance")
        for w in words or ():
            self._add_word(w)
        n = self._n
        first = self._analysed_n < self.lookahead_s * self.sr <= n  # the first update that can commit anything
        step = max(1, round(self.update_s * self.sr))  # then on a fixed grid of received time
        if first or n // step > self._analysed_n // step:
            self.update()
            return True
        return False

    def _add_word(self, w: tuple[str, float, float] | Word) -> None:
        self.words.append(parse_word(w, self.words[-1].start_s if self.words else -math.inf))

    def close(self) -> None:
        """The utterance is complete: flush the resampler and commit everything."""
        if self.closed:
            return
        if self._resampler is not None:
            tail = self._resampler.resample_chunk(np.zeros(0, np.float32), last=True)
            if tail.size:
                self._chunks.append(np.asarray(tail, np.float32))
        self.closed = True
        if self._n:
            self.update()

    # --- analysis -------------------------------------------------------------------------
    def _take_audio(self) -> np.ndarray:
        if self._chunks:
            self._audio = np.concatenate([self._audio, *self._chunks])
            self._chunks = []
        return self._audio

    def update(self) -> None:
        """Re-analyse (see module docstring) and move the commit points forward."""
        a = self._take_audio()
        n = a.shape[0]
        self._analysed_n = n
        if n == 0:
            return
        c = self.config
        now = n / self.sr
        final = self.closed
        commit = now if final else max(0.0, now - self.lookahead_s)

        volume, vrate = fine_volume(a, self.sr, c)
        self._noise = estimate_noise_level(volume, c)
        thresh = activity_threshold(self._noise, c)

        # onsets over the tail window; keep those past the committed ones
        hop = round(self.sr / vrate)
        w0 = max(0, n - round(self.window_s * self.sr)) // hop * hop
        t_w0 = w0 / self.sr
        found, peak = onset_envelope_peaks(a[w0:], self.sr, hop, self._env_max or None)
        found = found + t_w0
        self._env_max = max(self._env_max, peak)
        found = gate_onsets(found, volume, vrate, thresh)
        lo = self._onset_commit_s if w0 == 0 else max(self._onset_commit_s, t_w0 + _EDGE_S)
        hi = now if final else now - _EDGE_S
        fresh = [float(t) for t in found if lo <= t < hi]
        onset_commit = commit if final else max(self._onset_commit_s, min(commit, hi))
        self._onsets += [t for t in fresh if t < onset_commit]
        self._onset_commit_s = onset_commit
        provisional = [t for t in fresh if t >= onset_commit]

        beats, pseudo = identify_beats(
            np.asarray(self._onsets + provisional), volume, thresh, vrate, c.min_beat_gap_s, c.max_beat_gap_s,
            duration_s=now,
        )  # fmt: skip
        # A pseudo-beat depends on the next real onset (the end of its gap): final once that onset is.
        last = self._beats[-1] if self._beats else -np.inf
        last_real = self._onsets[-1] if self._onsets else -np.inf  # pseudo-beats before it no longer move
        for t, ps in zip(beats.tolist(), pseudo.tolist(), strict=True):
            if t <= last + 1e-9:
                continue
            if not final and (t >= commit or (ps and t > last_real)):
                break
            self._beats.append(t)
            self._pseudo.append(ps)
            last = t
        self.beat_commit_s = last if self._beats else 0.0
        later = beats > last + 1e-9 if self._beats else np.ones(beats.shape, bool)
        self._prov_beats, self._prov_pseudo = beats[later], pseudo[later]

        ws = [w for w in self.words if w.start_s < now]
        self._spans = silent_spans(volume, vrate, thresh, now, c.min_silence_s, ws)
        self._update_features(a, thresh, commit, final)

    def _update_features(self, a: np.ndarray, thresh: float, commit_s: float, final: bool) -> None:
        c, hop = self.config, self._feat_hop
        n_total = c.n_frames(a.shape[0], self.sr)
        f0 = max(0, self._feat_n - math.ceil(self.window_s * c.fps / 2))  # re-analyse a little before the commit
        f0 = max(0, min(f0, n_total - math.ceil(self.window_s * c.fps)))
        s0 = f0 * hop
        feats = acoustic_features(a[s0:], self.sr, c, thresh, spectral=self.spectral)  # frames f0.. on the same grid
        edge = 0 if final else math.ceil(_EDGE_S * c.fps)
        first = self._feat_n - f0
        n_commit = n_total if final else min(n_total - edge, math.floor(commit_s * c.fps))
        n_new = max(0, n_commit - self._feat_n)
        for k, v in feats.items():
            if n_new:
                self._feat[k].append(v[first : first + n_new])
            self._prov_feat[k] = v[first + n_new :]
        self._feat_n += n_new

    # --- output ---------------------------------------------------------------------------
    @property
    def beats_s(self) -> np.ndarray:
        """Committed beats, seconds ``(B,)``."""
        return np.asarray(self._beats, dtype=np.float64)

    @property
    def silent_spans(self) -> tuple[tuple[float, float], ...]:
        """Silent spans of the newest update (the last may still be open, ending at ``received_s``)."""
        return self._spans

    def speech(self, pad_s: float = 0.0, source: str = "stream") -> Speech:
        """A :class:`Speech` of everything received, committed and provisional, padded by ``pad_s`` seconds.

        The pad stands for speech not yet heard: its beats are guessed at the recent pace (``predict_beats``)
        and it counts as speech, except that a
        silence still open at the end of what was received continues through it (the speaker is
        pausing, so a generator keeps resting rather than leaving rest before the pause ends).
        Acoustic features in the pad repeat the last frame (pitch 0). The
        audio array holds the received samples followed by zeros for the pad.
        """
        a = self._take_audio()
        now = a.shape[0] / self.sr
        pad_n = 0 if self.closed else round(max(0.0, pad_s) * self.sr)
        total = now + pad_n / self.sr
        spans = list(self._spans)
        analysed = self._analysed_n / self.sr  # spans are from the last update, which may trail the newest chunk
        if pad_n and spans and spans[-1][1] >= analysed - 1e-9:
            spans[-1] = (spans[-1][0], total)
        beats = np.concatenate([self.beats_s, self._prov_beats])
        pseudo = np.concatenate([np.asarray(self._pseudo, bool), self._prov_pseudo])
        open_silence = bool(spans) and spans[-1][1] >= total - 1e-9
        if pad_n and self.predict_beats and not open_silence and beats.size:
            # Speech goes on: its beats continue at the recent pace (pseudo-beats, so a generator can prepare the
            # next stroke before its beat is heard; the heard beat replaces the guess within L).
            recent = np.diff(beats[-7:])
            c = self.config
            step = float(np.clip(np.median(recent), c.min_beat_gap_s, c.max_beat_gap_s)) if recent.size else 0.35
            guess = np.arange(beats[-1] + step, total - 1e-9, step)
            beats = np.concatenate([beats, guess])
            pseudo = np.concatenate([pseudo, np.ones(guess.shape, bool)])
        n_frames = self.config.n_frames(a.shape[0] + pad_n, self.sr)
        feats = {}
        for k in ("mel_db", "mfcc", "rms", "pitch_hz"):
            parts = [*self._feat[k], self._prov_feat.get(k, np.zeros((0,)))]
            parts = [p for p in parts if p.shape[0]]
            x = np.concatenate(parts) if parts else None
            if x is None:
                width = {"mel_db": (self.config.n_mels,), "mfcc": (37,)}.get(k, ())
                x = np.zeros((1, *width), np.float32)
            idx = np.minimum(np.arange(n_frames), x.shape[0] - 1)
            feats[k] = x[idx]
        if pad_n and "pitch_hz" in feats:
            n_real = self.config.n_frames(a.shape[0], self.sr)
            feats["pitch_hz"][n_real:] = 0.0
        words = tuple(w for w in self.words if w.end_s <= total)
        sf = speech_features(feats, words, spans, n_frames, self.config.fps)
        audio = np.concatenate([a, np.zeros(pad_n, np.float32)]) if pad_n else a
        return Speech(
            audio=audio,
            sr=self.sr,
            words=words,
            beats_s=beats,
            beat_is_pseudo=pseudo,
            silent_spans=tuple(spans),
            noise_level=self._noise,
            features=sf,
            source=source,
            text=" ".join(w.text for w in words),
            heard_s=now if pad_n else None,
        )


def stream_speech(
    audio: np.ndarray, sr: int, chunk_s: float = 0.02, lookahead_s: float = DEFAULT_LOOKAHEAD_S, **kwargs: object
) -> Speech:
    """Feed ``audio (N,)`` (int16 or float32) through a :class:`SpeechStream` in ``chunk_s`` chunks."""
    s = SpeechStream(sr, lookahead_s=lookahead_s, **kwargs)  # type: ignore[arg-type]
    step = max(1, round(chunk_s * sr))
    for i in range(0, len(audio), step):
        s.feed(audio[i : i + step])
    s.close()
    return replace(s.speech(), source="stream")
