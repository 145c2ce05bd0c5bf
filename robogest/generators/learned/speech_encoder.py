"""An optional pretrained speech encoder: a local wav2vec2-family checkpoint -> per-frame speech features.

The Rhythmic Gesticulator (Ao et al. 2022, §4.1.3) takes its high-level audio features from a pretrained speech
model, vq-wav2vec, fine-tuned with its contrastive loss. Its weights cannot be downloaded here, so by default the
model trains a convolutional encoder from scratch; a user who has a wav2vec2-family checkpoint on disk (a
``transformers`` folder: ``config.json`` + weights, e.g. ``facebook/wav2vec2-base-960h`` saved locally) can give
its path, and its last hidden layer becomes the high-level features (``--set speech_encoder=PATH``). Nothing is
downloaded: the folder is read with ``local_files_only``. The encoder is frozen (its features are computed once per
take), where the paper fine-tunes it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robogest.errors import InputError, MissingDependencyError

#: ``model_type`` values of ``transformers`` speech models that read the raw 16 kHz waveform through wav2vec2's
#: convolutional feature encoder followed by a transformer.
WAV2VEC2_FAMILY = ("wav2vec2", "wav2vec2-conformer", "hubert", "wavlm", "data2vec-audio", "unispeech", "unispeech-sat")
#: Seconds of audio per forward pass: self-attention grows with the square of the length, so long takes go in pieces.
CHUNK_S = 30.0


def _transformers() -> Any:
    try:
        import transformers
    except ImportError:
        from robogest.extras import install_command

        raise MissingDependencyError(
            f"a pretrained speech encoder needs the transformers package; install it with: {install_command('learn')}"
        ) from None
    return transformers


class PretrainedSpeechEncoder:
    """A frozen wav2vec2-family model read from a local folder.

    Parameters
    ----------
    path : path-like
        A ``transformers`` checkpoint folder (``config.json`` with a :data:`WAV2VEC2_FAMILY` ``model_type``, and its
        weights).
    device : str
        Torch device of the forward passes.

    Raises
    ------
    InputError
        The folder is missing, holds no readable config or weights, or another kind of model; the message names it.
    """

    def __init__(self, path: str | os.PathLike, device: str = "cpu") -> None:
        self.path = Path(path)
        tf = _transformers()
        if not (self.path / "config.json").is_file():
            raise InputError(
                f"speech encoder {self.path}: no config.json there; give the folder of a wav2vec2-family checkpoint "
                "saved with transformers (save_pretrained)"
            )
        try:
            config = tf.AutoConfig.from_pretrained(str(self.path), local_files_only=True)
        except (OSError, ValueError, KeyError) as e:
            raise InputError(f"speech encoder {self.path}: unreadable config.json ({e})") from None
        kind = getattr(config, "model_type", None)
        if kind not in WAV2VEC2_FAMILY:
            raise InputError(
                f"speech encoder {self.path}: a {kind!r} checkpoint, not a wav2vec2-family speech model "
                f"(model_type one of {', '.join(WAV2VEC2_FAMILY)})"
            )
        try:
            self.model = tf.AutoModel.from_pretrained(str(self.path), local_files_only=True).to(device).eval()
        except (OSError, ValueError, RuntimeError) as e:
            raise InputError(f"speech encoder {self.path}: its weights cannot be loaded ({e})") from None
        self.device = device
        self.dim = int(config.hidden_size)
        prep = self.path / "preprocessor_config.json"
        settings = json.loads(prep.read_text()) if prep.is_file() else {}
        self.sample_rate = int(settings.get("sampling_rate", 16000))
        self.normalize = bool(settings.get("do_normalize", True))  # zero mean, unit variance, as its extractor does
        strides, kernels = list(config.conv_stride), list(config.conv_kernel)
        self.hop = int(np.prod(strides))  # samples per output frame
        # receptive field of one output frame, samples: frame i covers [i * hop, i * hop + field)
        self.field = 1 + sum((k - 1) * int(np.prod(strides[:i])) for i, k in enumerate(kernels))

    def _encode(self, audio: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Last hidden layer ``(T', dim)`` of one piece of audio at :attr:`sample_rate`."""
        import torch

        x = audio.astype(np.float32)
        if self.normalize:
            x = (x - x.mean()) / np.sqrt(x.var() + 1e-7)
        with torch.inference_mode():
            out = self.model(torch.from_numpy(x)[None].to(self.device))
        hidden: npt.NDArray[np.float32] = out.last_hidden_state[0].float().cpu().numpy()
        return hidden

    def frames(self, audio: np.ndarray, sr: int, n_frames: int, fps: float) -> npt.NDArray[np.float32]:
        """Features ``(n_frames, dim)`` of ``audio`` ``(N,)`` at ``sr`` Hz, one per frame at ``fps``.

        Frame ``t`` gets the encoder's output whose receptive field is centred nearest ``t / fps`` (linear
        interpolation between outputs; the ends hold the first and last output).
        """
        if sr != self.sample_rate:
            raise InputError(
                f"speech encoder {self.path}: audio at {sr} Hz, the model reads {self.sample_rate} Hz; resample first"
            )
        a = np.asarray(audio, dtype=np.float32).reshape(-1)
        if a.size < self.field:  # shorter than one output frame: pad with silence
            a = np.pad(a, (0, self.field - a.size))
        chunk = max(1, round(CHUNK_S * sr / self.hop)) * self.hop  # a whole number of hops: outputs stay on one grid
        pieces = [self._encode(a[i : i + chunk]) for i in range(0, a.size, chunk) if a.size - i >= self.field]
        hidden = np.concatenate(pieces)  # (T', dim)
        centre = (np.arange(hidden.shape[0]) * self.hop + (self.field - 1) / 2) / sr  # (T',) seconds
        t_s = np.arange(n_frames) / fps
        out = np.empty((n_frames, self.dim), np.float32)
        for j in range(self.dim):
            out[:, j] = np.interp(t_s, centre, hidden[:, j])
        return out


_LOADED: dict[tuple[str, str], PretrainedSpeechEncoder] = {}


def load_speech_encoder(path: str | os.PathLike, device: str = "cpu") -> PretrainedSpeechEncoder:
    """:class:`PretrainedSpeechEncoder` of ``path``, loaded once per process and device."""
    key = (str(Path(path).resolve()), device)
    if key not in _LOADED:
        _LOADED[key] = PretrainedSpeechEncoder(path, device)
    return _LOADED[key]


def speech_frames(
    path: str | os.PathLike, audio: np.ndarray | None, sr: int, n_frames: int, fps: float
) -> npt.NDArray[np.float32]:
    """Features ``(n_frames, dim)`` of the encoder at ``path`` for a recording (:meth:`PretrainedSpeechEncoder.frames`).

    Raises
    ------
    InputError
        ``audio`` is None: the encoder reads the waveform, and frame features alone (a take without its recording)
        cannot feed it.
    """
    if audio is None:
        raise InputError(
            f"speech encoder {path}: reads the recording, and this take or speech has none (only frame features); "
            "give takes with their audio, or train without speech_encoder"
        )
    return load_speech_encoder(path).frames(audio, sr, n_frames, fps)
