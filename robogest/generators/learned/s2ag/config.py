"""S2AG inputs (MFCC from the cached log-mel, speaker keys) and hyper-parameters. Numpy only."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


def mfcc_from_mel(mel_db: np.ndarray) -> np.ndarray:
    """The speech front-end's 37 MFCC values from its log-mel spectrum (``SpeechFeatures.mfcc`` layout).

    ``librosa.feature.mfcc(S=mel_db)`` is an orthonormal DCT-II over the mel bands; taking it here lets training
    use the cached mel features (the frame-grid interpolation is linear, so the order does not matter).

    Parameters
    ----------
    mel_db : ndarray [shape=(T, 64)], dB

    Returns
    -------
    ndarray [shape=(T, 37)]
        c0..c12, forward differences of c1..c12, their forward differences (last rows 0).
    """
    from scipy.fft import dct

    from robogest.speech.features import N_MFCC, forward_diff

    cep = dct(np.asarray(mel_db, np.float64), type=2, norm="ortho", axis=1)[:, :N_MFCC]  # (T, 13)
    d1 = forward_diff(cep[:, 1:])  # (T, 12)
    return np.concatenate([cep, d1, forward_diff(d1)], axis=1).astype(np.float32)  # (T, 37)


@dataclass(frozen=True)
class S2AGConfig:
    """Hyper-parameters (Table 1, §4) and the data statistics a checkpoint needs.

    Attributes
    ----------
    n_mfcc, n_text : int
        MFCC values (37) and text-vector size per frame (384 for MiniLM).
    speakers : tuple of str
        Speaker keys (:func:`speaker_key`) in one-hot order; ``len`` is S.
    fps : float
        Frame rate of the model's inputs and outputs (the trainer's feature rate, 20 fps).
    window_s, seed_s : float
        Window length and known seed poses at its start, seconds: the paper's T = 34 and 4 frames at its 15 fps
        (2.27 s and 0.27 s), so at 20 fps :attr:`seq_len` = 45 and :attr:`n_seed` = 5 frames cover the same time.
    d_mfcc, d_text, d_style : int
        D_m = 32, D_x = 32, D_s = 16.
    d_aff1, d_aff2, d_aff : int
        D_a1 = D_a2 = D_a = 16.
    d_gen, d_disc : int
        GRU widths D_e = D_d = 150.
    gru_layers : int
        Layers of both bidirectional GRUs: 4, the authors' code (``n_layers: 4`` in its
        ``config/multimodal_context_v2.yml``; the paper gives no depth).
    dropout : float
        Between GRU layers.
    lr_generator, lr_discriminator, beta1 : float
        Adam settings (5e-4, 1e-4, 0.5; §4); ``robogest train --lr`` does not apply to this model.
    w_huber, w_gan, w_div, w_kld : float
        Loss weights λ (eq. 15), Yoon et al.'s values (500, 5, 0.05, 0.1).
    huber_beta : float
        Huber transition point on the direction vectors (0.1, Yoon et al.).
    mfcc_mean, mfcc_std : tuple of float
        MFCC normalisation from the training takes (37 each; empty until fitted).
    dir_mean : tuple of float
        Mean unit edge direction (27), subtracted from the model's pose space.
    val_windows : int
        Chained windows per held-out rollout (3: 6.25 s at 20 fps), so ``best.pt`` is chosen on windows seeded by
        the model's own poses, as generation runs (:attr:`validation_length`).
    """

    n_mfcc: int = 37
    n_text: int = 384
    speakers: tuple[str, ...] = ("default",)
    fps: float = 20.0
    window_s: float = 34 / 15
    seed_s: float = 4 / 15
    d_mfcc: int = 32
    d_text: int = 32
    d_style: int = 16
    d_aff1: int = 16
    d_aff2: int = 16
    d_aff: int = 16
    d_gen: int = 150
    d_disc: int = 150
    gru_layers: int = 4
    dropout: float = 0.1
    lr_generator: float = 5e-4
    lr_discriminator: float = 1e-4
    beta1: float = 0.5
    w_huber: float = 500.0
    w_gan: float = 5.0
    w_div: float = 0.05
    w_kld: float = 0.1
    huber_beta: float = 0.1
    mfcc_mean: tuple[float, ...] = ()
    mfcc_std: tuple[float, ...] = ()
    dir_mean: tuple[float, ...] = ()
    val_windows: int = 3

    @property
    def seq_len(self) -> int:
        """Window length T, frames."""
        return round(self.window_s * self.fps)

    @property
    def n_seed(self) -> int:
        """Known seed frames at the start of a window."""
        return max(1, round(self.seed_s * self.fps))

    @property
    def validation_length(self) -> int:
        """Frames of one held-out rollout: :attr:`val_windows` windows chained by their seed frames."""
        return self.n_seed + max(1, self.val_windows) * (self.seq_len - self.n_seed)

    @property
    def n_speakers(self) -> int:
        return len(self.speakers)

    @property
    def n_input(self) -> int:
        """Columns of a training window's speech array: normalised MFCC, text, speaker index."""
        return self.n_mfcc + self.n_text + 1

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> S2AGConfig:
        d = dict(d)
        fps = float(d.get("fps", cls.fps))
        if "seq_len" in d:  # checkpoints before windows were set in seconds
            d["window_s"] = d.pop("seq_len") / fps
        if "n_seed" in d:
            d["seed_s"] = d.pop("n_seed") / fps
        for k in ("speakers", "mfcc_mean", "mfcc_std", "dir_mean"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)
