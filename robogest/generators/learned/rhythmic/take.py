"""A whole take or speech -> beat blocks: the one path of training and inference (§4.2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogest.data.prep import Normalization
from robogest.generators.learned.rhythmic.blocks import (
    clip_bounds,
    frame_beats,
    normalize_clips,
    quiet_frames,
    silent_blocks,
    tsm_mel_blocks,
)
from robogest.generators.learned.rhythmic.config import TEXT_SCALE, RhythmicConfig
from robogest.generators.learned.speech_encoder import speech_frames


# --------------------------------------------------------------------------------------------------- beat rhythm
def take_rhythm(
    mel: np.ndarray, mel_db: np.ndarray, text: np.ndarray, c: RhythmicConfig, beats_s: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Clip bounds and silent clips of a whole take or speech: the one rule of training and inference.

    Parameters
    ----------
    mel : ndarray [shape=(T, n_mels)]
        Standardised log-mel (``Normalization.acoustic`` of the take's or speech's acoustic features).
    mel_db : ndarray [shape=(T, n_mels)]
        The same log-mel before standardisation, dB (for :func:`.blocks.quiet_frames`).
    text : ndarray [shape=(T, D)]
        Raw text features (frames outside words are the silence vector, -15).
    c : RhythmicConfig
    beats_s : ndarray [shape=(B,)], seconds, optional
        Beats by the speech front-end's rule on the waveform (``Speech.beats_s``, :func:`take_beats`): the paper's
        §4.2.1 cut. Without them (features but no recording) the beats come from the log-mel frames instead.

    Returns
    -------
    bounds : ndarray [shape=(C + 1,)], int
        From beats by :func:`.blocks.frame_beats` (which applies the speech module's
        :func:`~robogest.speech.beats.identify_beats`) on ``mel``.
    silent : ndarray [shape=(C,)], bool
        :func:`.blocks.silent_blocks` (words from ``text``, quiet frames from ``mel_db``).
    """
    if beats_s is None:
        beats_s = frame_beats(mel, c.fps, c.min_beat_gap_s, c.max_beat_gap_s)
    bounds = clip_bounds(np.asarray(beats_s, np.float64), mel.shape[0], c.fps)
    silent = silent_blocks(bounds, word_frames(text), quiet_frames(mel_db), c.quiet_share)
    return bounds, silent


def word_frames(text: np.ndarray) -> np.ndarray:
    """Frames ``(T,)`` inside a word: text features other than the silence vector (raw scale, -15)."""
    inside: np.ndarray = ~np.all(text <= -TEXT_SCALE + 1e-3, axis=1)
    return inside


@dataclass
class TakeBlocks:
    """A whole take or speech as beat blocks (numpy), made by :func:`take_blocks`.

    Attributes
    ----------
    bounds : ndarray [shape=(C + 1,)], int
        Clip boundaries, frames.
    silent : ndarray [shape=(C,)], bool
        Silent blocks (§6.4.1).
    mel : ndarray [shape=(C, K, n_mels)], float32
        Standardised log-mel of the time-scaled audio.
    text : ndarray [shape=(C, K, D)], float32
        Raw text features, resampled.
    poses : ndarray [shape=(C, K, P)], float32, optional
        Normalised exponential maps, resampled (training takes only).
    """

    bounds: np.ndarray
    silent: np.ndarray
    mel: np.ndarray
    text: np.ndarray
    poses: np.ndarray | None = None


def take_blocks(
    mel_db: np.ndarray,
    text: np.ndarray,
    norm: Normalization,
    c: RhythmicConfig,
    audio: np.ndarray | None = None,
    poses: np.ndarray | None = None,
    beats_s: np.ndarray | None = None,
    tsm_db: np.ndarray | None = None,
) -> TakeBlocks:
    """Cut a whole take or speech at its beats and normalise every clip to a block (§4.2): the one path from
    frames to blocks for training and inference.

    Parameters
    ----------
    mel_db : ndarray [shape=(T, n_mels)], dB
        Front-end log-mel.
    text : ndarray [shape=(T, D)]
        Raw text features.
    norm : Normalization
        Training statistics (its first ``n_mels`` acoustic columns standardise the log-mel).
    c : RhythmicConfig
    audio : ndarray [shape=(N,)], float32, optional
        The samples at ``c.audio_sr`` Hz, frame ``t`` at sample ``t * audio_sr / fps``: with ``c.audio_tsm`` the
        audio blocks are time-scaled audio re-analysed (:func:`.blocks.tsm_mel_blocks`); without it the
        log-mel frames are resampled.
    poses : ndarray [shape=(T, P)], radians, optional
        Exponential maps (a training take), returned normalised and in blocks.
    beats_s : ndarray [shape=(B,)], seconds, optional
        The speech's beats (``Speech.beats_s``); None: :func:`take_beats` of ``audio`` when given, else beats of
        the log-mel frames (:func:`take_rhythm`).
    tsm_db : ndarray [shape=(C, K, n_mels)], dB, optional
        The time-scaled audio blocks of these beats, already computed (:func:`.cache.take_rhythm_blocks`): used
        instead of ``audio`` for the audio blocks.
    """
    m = c.n_mels
    mean, std = norm.acoustic_mean[:m], norm.acoustic_std[:m]
    mel = ((mel_db - mean) / std).astype(np.float32)  # (T, M) standardised
    if beats_s is None and audio is not None:
        beats_s = take_beats(audio, c)
    bounds, silent = take_rhythm(mel, mel_db, text, c, beats_s)
    k = c.block
    if tsm_db is not None:
        mel_blocks = (tsm_db - mean) / std
    elif audio is not None and c.audio_tsm:
        mel_blocks = (tsm_mel_blocks(audio, c.audio_sr, bounds, c.fps, k, m, c.mel_window_s) - mean) / std
    else:
        mel_blocks = normalize_clips(mel, bounds, k)
    if c.speech_encoder:  # the pretrained encoder's features, cut into the same blocks: a_high (speech_encoder.py)
        speech = speech_frames(c.speech_encoder, audio, c.audio_sr, mel.shape[0], c.fps)  # (T, speech_dim)
        mel_blocks = np.concatenate([mel_blocks, normalize_clips(speech, bounds, k)], axis=2)  # (C, K, n_audio)
    pose_blocks = normalize_clips(norm.pose(poses), bounds, k) if poses is not None else None
    return TakeBlocks(bounds, silent, mel_blocks.astype(np.float32), normalize_clips(text, bounds, k), pose_blocks)


def take_beats(audio: np.ndarray, c: RhythmicConfig) -> np.ndarray:
    """Beats ``(B,)`` s of a recording at ``c.audio_sr`` Hz by the speech front-end's §4.2.1 rule
    (:func:`robogest.speech.audio_beats`, the same as ``Speech.beats_s`` at run time)."""
    from robogest.speech import audio_beats
    from robogest.speech.config import SpeechConfig

    cfg = SpeechConfig(sr=c.audio_sr, fps=c.fps, min_beat_gap_s=c.min_beat_gap_s, max_beat_gap_s=c.max_beat_gap_s)
    return audio_beats(audio, c.audio_sr, cfg)[0]
