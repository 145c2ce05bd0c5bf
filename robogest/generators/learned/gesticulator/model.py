"""Gesticulator (Kucherenko et al., ICMI 2020, §4): audio + text in, autoregressive joint rotations out.

Importing this module needs PyTorch (``pip install 'robogest[learn]'``); without it the import raises
:class:`~robogest.errors.MissingDependencyError`, so register the generator through a lazy factory.

Per frame at 20 fps the model reads 64 log-mel bands, the five Table 1 word-timing features and the text encoder's
vector (§3.2). A frame encoder reduces each frame to 124 values; a sliding window of 10 past frames, the current
frame and 19 future frames (30 frames = 0.5 s back, 1 s ahead, 3720 values, §4.4) passes through fully connected
layers 612 -> 256 -> output with tanh and dropout 0.2. The previous 3 output poses are encoded into a 512-d
conditioning vector (dropout 0.8) that FiLM-modulates the 612-unit layer (§4.2). The output is the canonical
skeleton's joint rotations as exponential maps, normalised per dimension (the paper's final, no-PCA model), or with
``pca_variance`` > 0 the coefficients of a PCA fitted on the training poses (the paper's PCA variant, :mod:`.pca`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robogest.learn import require_torch

if TYPE_CHECKING:  # the real modules for the type checker; at run time the import names the extra to install
    import torch
    from torch import Tensor, nn
    from torch.nn import functional as F
else:
    torch = require_torch("the 'gesticulator' generator")
    nn = torch.nn
    F = torch.nn.functional
    Tensor = torch.Tensor


#: Velocity-loss weight λ (§4.3).
VELOCITY_WEIGHT = 0.6
#: Ground-truth-pose period per autoregressive epoch before full teacher forcing (§4.3); 0 = never.
TEACHER_FORCING_PERIODS = (0, 16, 8, 4)
#: Consecutive frames fed the ground truth at each teacher-forcing point (§4.3: "for two consecutive frames").
TEACHER_FORCING_RUN = 2


@dataclass(frozen=True)
class GesticulatorConfig:
    """Model hyper-parameters (defaults: §4.2-4.4).

    Attributes
    ----------
    n_acoustic, n_text, n_pose : int
        Input acoustic+timing features (64 + 5), text features (384 for MiniLM), output values (17 joints x 3).
    frame_dim : int
        Frame encoding size (124).
    past, future : int
        Window frames before the current one (10) and from the current one on (20, i.e. 1 s ahead).
    hidden : tuple of int
        Sizes of the fully connected layers after the window (612, 256).
    n_prev_poses : int
        Poses fed back (3).
    cond_dim : int
        Conditioning vector size (512).
    dropout, pose_dropout : float
        Dropout of every layer (0.2) and of the pose encoding (0.8).
    train_frames : int
        Predicted frames per training sequence (40); sequences are ``past + train_frames + future`` = 70 long.
    pretrain_epochs : int
        Epochs without autoregression before the teacher-forcing schedule (7).
    pca_variance : float
        0 (default): no PCA, the paper's final model (§6.2). In (0, 1]: the model predicts, and feeds back, the
        coefficients of a PCA of the normalised training poses that keeps this fraction of their variance (§5.1:
        0.95, 12 components on Trinity); the poses are the coefficients times :attr:`pca_components`.
    pca_components : tuple of tuple of float
        ``(K, n_pose)`` orthonormal rows, filled from the training split by ``GesticulatorSpec.fit_config`` (and
        so stored in the checkpoint's model config); empty without PCA. Normalised training poses have zero mean,
        so no mean is stored.
    """

    n_acoustic: int = 69
    n_text: int = 384
    n_pose: int = 51
    frame_dim: int = 124
    past: int = 10
    future: int = 20
    hidden: tuple[int, int] = (612, 256)
    n_prev_poses: int = 3
    cond_dim: int = 512
    dropout: float = 0.2
    pose_dropout: float = 0.8
    train_frames: int = 40
    pretrain_epochs: int = 7
    pca_variance: float = 0.0
    pca_components: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.past < self.n_prev_poses:  # the autoregressive input is the n_prev_poses frames before the first
            raise ValueError(f"past={self.past} must be at least n_prev_poses={self.n_prev_poses}")
        if self.train_frames < 1:
            raise ValueError(f"train_frames={self.train_frames} must be at least 1")
        if not 0.0 <= self.pca_variance <= 1.0:
            raise ValueError(f"pca_variance={self.pca_variance} must be 0 (no PCA) or a fraction in (0, 1]")
        if any(len(row) != self.n_pose for row in self.pca_components):
            raise ValueError(f"pca_components rows must have n_pose={self.n_pose} values")
        if self.pca_components and self.pca_variance == 0.0:
            raise ValueError("pca_components are given but pca_variance is 0: set the fraction they were fitted for")

    @property
    def n_out(self) -> int:
        """Values the network predicts per frame: PCA coefficients, or the normalised pose itself."""
        return len(self.pca_components) or self.n_pose

    @property
    def n_input(self) -> int:
        return self.n_acoustic + self.n_text

    @property
    def window(self) -> int:
        return self.past + self.future

    @property
    def sequence_length(self) -> int:
        return self.past + self.train_frames + self.future

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GesticulatorConfig:
        d = dict(d)
        d["hidden"] = tuple(d.get("hidden", cls.hidden))
        d["pca_components"] = tuple(tuple(float(v) for v in row) for row in d.get("pca_components", ()))
        return cls(**d)


def teacher_forcing_period(epoch: int, pretrain_epochs: int = 7) -> int | None:
    """Autoregression mode of 0-based ``epoch``, following Gesticulator §4.3.

    "we pretrain our model without autoregression for the first seven epochs [...] full training begins without
    any teacher forcing [...] after one epoch, the model receives the ground-truth poses instead of its own
    prediction (for two consecutive frames) every 16 frames, which increased to every eight frames after another
    epoch, to every four frames after the next epoch, and then to every single frame after that."

    Returns
    -------
    int or None
        ``None``: no autoregression (epochs 0-6); ``0``: own predictions only (epoch 7); ``16``, ``8``, ``4``:
        ground truth for :data:`TEACHER_FORCING_RUN` frames every that many frames (epochs 8, 9, 10); ``1``: ground
        truth always (epoch 11 on).
    """
    if epoch < pretrain_epochs:
        return None
    k = epoch - pretrain_epochs
    return TEACHER_FORCING_PERIODS[k] if k < len(TEACHER_FORCING_PERIODS) else 1


def uses_ground_truth(frame: int, period: int | None) -> bool:
    """Whether predicted frame ``frame`` (0-based within the sequence) feeds back the ground truth."""
    if period is None or period == 0:
        return False
    return period == 1 or frame % period < TEACHER_FORCING_RUN


class GesticulatorNet(nn.Module):
    """The network of §4.2 / Fig. 3."""

    pca_basis: Tensor | None  # buffer (K, n_pose), or None without PCA

    def __init__(self, config: GesticulatorConfig) -> None:
        super().__init__()
        c = config
        self.config = c
        h1, h2 = c.hidden
        if c.pca_variance > 0 and not c.pca_components:
            raise ValueError(
                f"pca_variance={c.pca_variance} but no pca_components: fit them on the training takes with "
                "GesticulatorSpec.fit_config (robogest train does) before building the network"
            )
        self.frame_encoder = nn.Sequential(nn.Linear(c.n_input, c.frame_dim), nn.Tanh(), nn.Dropout(c.dropout))
        self.layer1 = nn.Sequential(nn.Linear(c.window * c.frame_dim, h1), nn.Tanh(), nn.Dropout(c.dropout))
        self.layer2 = nn.Sequential(nn.Linear(h1, h2), nn.Tanh(), nn.Dropout(c.dropout))
        self.output = nn.Linear(h2, c.n_out)  # linear: the output range is not restricted (§4.2)
        self.pose_encoder = nn.Sequential(
            nn.Linear(c.n_prev_poses * c.n_out, c.cond_dim), nn.Tanh(), nn.Dropout(c.pose_dropout)
        )
        # (K, P) PCA basis from the config, not a weight: the config in the checkpoint is its one stored copy
        basis = torch.tensor(c.pca_components, dtype=torch.float32) if c.pca_components else None
        self.register_buffer("pca_basis", basis, persistent=False)
        self.film = nn.Linear(c.cond_dim, 2 * h1)  # linear (§4.2); -> (gamma, beta)
        nn.init.zeros_(self.film.weight)  # starts as the identity FiLM, so switching autoregression on is smooth
        nn.init.zeros_(self.film.bias)

    def encode_windows(self, speech: Tensor) -> Tensor:
        """Speech frames -> first hidden layer of every complete window.

        Parameters
        ----------
        speech : Tensor [shape=(B, L, n_input)]

        Returns
        -------
        Tensor [shape=(B, L - window + 1, hidden[0])]
            Entry ``k`` belongs to the pose of frame ``k + past``.
        """
        c = self.config
        enc = self.frame_encoder(speech)  # (B, L, frame_dim)
        win = enc.unfold(1, c.window, 1)  # (B, L - W + 1, frame_dim, W)
        win = win.transpose(2, 3).flatten(2)  # (B, L - W + 1, W * frame_dim), frames oldest first
        out: Tensor = self.layer1(win)  # (B, L - W + 1, h1)
        return out

    def to_output_space(self, poses: Tensor) -> Tensor:
        """Normalised poses ``(..., n_pose)`` -> what the network predicts ``(..., n_out)`` (PCA coefficients)."""
        return poses if self.pca_basis is None else poses @ self.pca_basis.T

    def from_output_space(self, out: Tensor) -> Tensor:
        """The network's outputs ``(..., n_out)`` -> normalised poses ``(..., n_pose)``."""
        return out if self.pca_basis is None else out @ self.pca_basis

    def decode(self, h: Tensor, prev: Tensor | None) -> Tensor:
        """One pose from a window's first hidden layer and the previous poses (fed back in the output space).

        Parameters
        ----------
        h : Tensor [shape=(B, hidden[0])]
        prev : Tensor [shape=(B, n_prev_poses, n_pose)] or None
            None: no autoregression (FiLM off, the pre-training mode).

        Returns
        -------
        Tensor [shape=(B, n_pose)]
        """
        if prev is not None:
            cond = self.pose_encoder(self.to_output_space(prev).flatten(1))  # (B, 3, K) -> (B, 3K) -> (B, cond_dim)
            gamma, beta = self.film(cond).chunk(2, dim=-1)  # (B, h1) each
            h = h * (1.0 + gamma) + beta  # FiLM(x, α, β) = x * α + β with α = 1 + γ
        return self.from_output_space(self.output(self.layer2(h)))

    def forward(self, speech: Tensor, poses: Tensor | None = None, period: int | None = None) -> Tensor:
        """Poses for the frames of ``speech`` that have a full window.

        Parameters
        ----------
        speech : Tensor [shape=(B, L, n_input)]
        poses : Tensor [shape=(B, L, n_pose)], optional
            Ground truth (normalised): frames ``past - 3 .. past - 1`` seed the autoregression and teacher
            forcing reads the rest. Without it the seed is the mean pose (zeros).
        period : int or None
            :func:`teacher_forcing_period`; None: no autoregression.

        Returns
        -------
        Tensor [shape=(B, L - window, n_pose)]
            Poses of frames ``past .. L - future - 1``.
        """
        c = self.config
        n_pred = speech.shape[1] - c.window
        h1 = self.encode_windows(speech)[:, :n_pred]  # (B, n_pred, h1)
        if period is None:
            return self.from_output_space(self.output(self.layer2(h1)))  # (B, n_pred, P), all frames at once
        b = speech.shape[0]
        if poses is not None:
            prev = poses[:, c.past - c.n_prev_poses : c.past]  # (B, 3, P)
        else:
            prev = speech.new_zeros(b, c.n_prev_poses, c.n_pose)
        outs = []
        for k in range(n_pred):
            y = self.decode(h1[:, k], prev)  # (B, P)
            outs.append(y)
            fed = poses[:, c.past + k] if poses is not None and uses_ground_truth(k, period) else y
            prev = torch.cat([prev[:, 1:], fed[:, None]], dim=1)  # (B, 3, P): drop oldest, append newest
        return torch.stack(outs, dim=1)  # (B, n_pred, P)


def gesture_loss(pred: Tensor, target: Tensor) -> Tensor:
    """MSE + λ·MSE of the frame-to-frame velocities (§4.3), λ = 0.6; both ``(B, T, P)``."""
    vel = F.mse_loss(pred[:, 1:] - pred[:, :-1], target[:, 1:] - target[:, :-1])
    return F.mse_loss(pred, target) + VELOCITY_WEIGHT * vel
