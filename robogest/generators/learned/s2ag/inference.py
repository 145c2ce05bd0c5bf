"""S2AG inference: window after window, each seeded with the previous one's last poses."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from robogest.data.features import speech_inputs
from robogest.errors import InputError
from robogest.generators.learned.checkpoint import CheckpointGenerator
from robogest.generators.learned.s2ag.config import S2AGConfig
from robogest.generators.learned.s2ag.networks import S2AGNet, torch
from robogest.generators.learned.s2ag.skeleton import N_EDGES, directions_to_motion
from robogest.motion.human_motion import HumanMotion
from robogest.speech.types import Speech


class S2AGGenerator(CheckpointGenerator):
    """Generator backed by a checkpoint from ``robogest train --model s2ag``.

    Parameters
    ----------
    checkpoint : path-like
        ``.pt`` file (model config with speaker table and statistics, feature config).
    speaker : None, int, "sample" or array-like of shape (D_s,)
        Style: ``None`` the training speakers' average style (mean of their means); an int that speaker's mean
        style; ``"sample"`` a new style drawn from N(0, I) with ``generate``'s seed; a vector a given style (e.g.
        an interpolation of :meth:`style_vector` results).
    device : str
        Torch device for inference.
    encoder : TextEncoder, optional
        Overrides the text encoder the checkpoint names (same dimension).
    """

    name = "s2ag"

    config_cls = S2AGConfig
    net_cls = S2AGNet
    model: S2AGNet  # the base keeps whichever family's network and config it loaded: here these
    config: S2AGConfig

    def configure(self, speaker: npt.ArrayLike | None = None, **options: Any) -> None:
        """Check the model's data statistics and set the style ``speaker`` (see the class); any other option is
        refused (:meth:`CheckpointGenerator.configure`)."""
        super().configure(**options)
        if not self.config.mfcc_mean or not self.config.dir_mean:
            raise InputError("the s2ag model config has no data statistics (it was never fitted to a dataset)")
        self.speaker = speaker
        self.style_vector(speaker, 0)  # validate now, not at the first generate

    def style_vector(self, speaker: npt.ArrayLike | None = None, seed: int = 0) -> np.ndarray:
        """The style ``z`` ``(D_s,)`` that ``speaker`` (see the class) stands for."""
        c = self.config
        if isinstance(speaker, str) and speaker == "sample":
            g = torch.Generator().manual_seed(int(seed))
            return np.asarray(torch.randn(c.d_style, generator=g).numpy())
        with torch.inference_mode():
            if speaker is None:
                mu, _ = self.model.generator.style(torch.arange(c.n_speakers, device=self.device))  # (S, D_s)
                return np.asarray(mu.mean(0).cpu().numpy())
            if isinstance(speaker, (int, np.integer)) and not isinstance(speaker, bool):
                if not 0 <= int(speaker) < c.n_speakers:
                    raise InputError(f"speaker {speaker} out of range: the model knows {c.n_speakers} ({c.speakers})")
                mu, _ = self.model.generator.style(torch.tensor([int(speaker)], device=self.device))
                return np.asarray(mu[0].cpu().numpy())
        z = np.asarray(speaker, dtype=np.float32)
        if z.shape != (c.d_style,):
            raise InputError(f"speaker must be None, an int, 'sample' or a {c.d_style}-vector, got {speaker!r}")
        return z

    def inputs(self, speech: Speech) -> tuple[np.ndarray, np.ndarray]:
        """Normalised MFCC ``(T, 37)`` and text vectors ``(T, n_text)`` (re-analysed when the fps differs)."""
        speech = self.at_model_rate(speech)
        _, text = speech_inputs(speech, self.features, self.encoder)  # (T, D)
        c = self.config
        mfcc = (speech.features.mfcc - np.asarray(c.mfcc_mean, np.float32)) / np.asarray(c.mfcc_std, np.float32)
        return mfcc.astype(np.float32), text.astype(np.float32)

    def predict(self, mfcc: np.ndarray, text: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Unit edge directions ``(T, 9, 3)`` for normalised inputs, window after window.

        Window ``k`` covers frames ``[k s, k s + T)`` with ``s = T - n_seed``; its seed is the previous window's
        last ``n_seed`` poses (the first window's is the mean pose). Inputs are padded with their last frame.
        """
        c = self.config
        n = mfcc.shape[0]
        if n == 0:
            return np.zeros((0, N_EDGES, 3), np.float32)
        step = c.seq_len - c.n_seed
        n_win = max(1, math.ceil((n - c.n_seed) / step))
        total = c.n_seed + n_win * step
        pad = np.minimum(np.arange(total), n - 1)  # edge padding
        x_m = torch.from_numpy(mfcc[pad]).to(self.device)[None]  # (1, total, 37)
        x_t = torch.from_numpy(text[pad]).to(self.device)[None]  # (1, total, D)
        zt = torch.from_numpy(np.asarray(z, np.float32)).to(self.device)[None]  # (1, D_s)
        with torch.inference_mode():
            out = self.model.generator.rollout(x_m, x_t, zt)[0]  # (total, 27)
        y = out[:n].cpu().numpy() + np.asarray(c.dir_mean, np.float32)  # (n, 27)
        y = y.reshape(n, N_EDGES, 3)  # (n, 27) -> (n, 9, 3)
        return np.asarray(y / np.maximum(np.linalg.norm(y, axis=-1, keepdims=True), 1e-9), dtype=np.float32)

    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion at ``speech.fps`` lasting as long as the speech; ``seed`` only matters for ``speaker="sample"``."""
        torch.manual_seed(seed)
        mfcc, text = self.inputs(speech)
        dirs = self.predict(mfcc, text, self.style_vector(self.speaker, seed))  # (T, 9, 3)
        return directions_to_motion(dirs, self.features.fps).resample(speech.fps, n_frames=speech.n_frames)
