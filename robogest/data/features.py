"""Model inputs and targets from speech and motion, shared by training (datasets) and generation.

One function builds the per-frame inputs from a :class:`~robogest.speech.types.Speech`, so a model sees exactly
the same features when it is trained and when it gestures.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.errors import InputError
from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M
from robogest.speech.config import SpeechConfig
from robogest.speech.types import Speech

if TYPE_CHECKING:
    from robogest.text import TextEncoder

#: Bump when the meaning of cached arrays changes; part of every cache key.
FEATURE_VERSION = 1


@dataclass(frozen=True)
class FeatureConfig:
    """How speech and motion become arrays; stored in every checkpoint and hashed into cache keys.

    Attributes
    ----------
    fps : float
        Frame rate of inputs and outputs, frames/s (20, Gesticulator §4.1).
    text_encoder : str
        Registered text encoder name (:func:`robogest.text.make_text_encoder`).
    text_encoder_kwargs : dict
        Arguments of that encoder (e.g. ``{"dim": 16}`` for ``hash-test``).
    speech : dict
        :class:`~robogest.speech.config.SpeechConfig` fields other than ``fps``; defaults when empty.
    """

    fps: float = 20.0
    text_encoder: str = "minilm"
    text_encoder_kwargs: dict[str, Any] = field(default_factory=dict)
    speech: dict[str, Any] = field(default_factory=dict)

    def speech_config(self) -> SpeechConfig:
        return SpeechConfig(**{**self.speech, "fps": self.fps})

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FeatureConfig:
        return cls(**d)

    def key(self) -> str:
        """Stable hash of the config (and :data:`FEATURE_VERSION`), hex."""
        blob = json.dumps({"v": FEATURE_VERSION, **self.to_dict()}, sort_keys=True, default=str)
        return hashlib.sha1(blob.encode()).hexdigest()[:16]


def text_encoder_for(config: FeatureConfig) -> TextEncoder:
    from robogest.text import make_text_encoder

    return make_text_encoder(config.text_encoder, **config.text_encoder_kwargs)


def speech_inputs(
    speech: Speech, config: FeatureConfig, encoder: TextEncoder | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame acoustic/timing and text inputs of ``speech``.

    Parameters
    ----------
    speech : Speech
        Analysed at ``config.fps`` (re-analyse it otherwise).
    config : FeatureConfig
    encoder : TextEncoder, optional
        Default: the one ``config`` names.

    Returns
    -------
    acoustic : ndarray [shape=(T, 64 + 5)], float32
        Log-mel (dB) then the five Table 1 word timing features (s, s, s, fraction, syllables/s).
    text : ndarray [shape=(T, D)], float32
        Text encoder features per frame (§3.2).
    """
    if abs(speech.fps - config.fps) > 1e-6:
        raise InputError(f"speech features are at {speech.fps} fps, the model needs {config.fps} fps")
    f = speech.features
    acoustic = np.concatenate([f.mel_db, f.word_features], axis=1).astype(np.float32)  # (T, 64 + 5)
    enc = encoder if encoder is not None else text_encoder_for(config)
    text = enc.frame_features(speech.words, f.n_frames, config.fps)  # (T, D)
    return acoustic, text


def motion_to_expmap(motion: HumanMotion) -> np.ndarray:
    """Canonical motion -> exponential maps ``(T, J * 3)`` radians (joint-major), Gesticulator §4.1 without PCA."""
    if motion.skeleton.n_joints != CANONICAL.n_joints:
        raise InputError(f"motion must be on the canonical skeleton ({CANONICAL.n_joints} joints)")
    rv = R.to_axis_angle(motion.rotations)  # (T, J, 4) -> (T, J, 3)
    return rv.reshape(rv.shape[0], -1).astype(np.float32)  # (T, J * 3)


def expmap_to_motion(poses: np.ndarray, fps: float) -> HumanMotion:
    """Exponential maps ``(T, J * 3)`` -> canonical :class:`HumanMotion`, the root at its rest position."""
    poses = np.asarray(poses, dtype=np.float64)
    rot = R.from_axis_angle(poses.reshape(poses.shape[0], CANONICAL.n_joints, 3))  # (T, J*3) -> (T, J, 3) -> (T, J, 4)
    root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (poses.shape[0], 1))  # (T, 3)
    return HumanMotion(fps=fps, rotations=R.normalize(rot), root_pos_m=root, skeleton=CANONICAL)
