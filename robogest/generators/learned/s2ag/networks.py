"""Speech2AffectiveGestures (Bhattacharya et al., ACM MM 2021, §3-4): MFCC + text + speaker style + seed poses in,
upper-body edge directions out, trained as a GAN whose discriminator sees the affective encoder's features.

Importing this module needs PyTorch (``pip install 'robogest[learn]'``); without it the import raises
:class:`~robogest.errors.MissingDependencyError`, so register the generator through a lazy factory.

Data path (all at the feature rate, 20 fps):

* **MFCC** (37 per frame, §3.1.1): computed from the take's stored 64-band log-mel spectrum by the same DCT-II the
  speech front-end uses (:func:`mfcc_from_mel`), so training needs no new cached arrays and equals
  ``Speech.features.mfcc`` at inference exactly (DCT and the frame interpolation are both linear).
* **Text** (§3.1.2): the paper's FastText 300-d vectors cannot be downloaded here; the take's per-frame vectors from
  the registered text encoder are used instead (MiniLM, 384-d contextual per word, by default; any registered
  encoder works, the checkpoint records which).
* **Speaker** (§3.1.3): :func:`speaker_key` of the take name (BEAT2 names start with the speaker number; any other
  name is the single speaker ``"default"``); the speaker table is stored in the model config.
* **Poses** (§3.1.4): 9 unit edge directions over 10 joints (:data:`JOINTS`, :data:`EDGES`) from the canonical
  skeleton's forward kinematics, minus the training mean direction; back to canonical rotations by per-bone swings
  (:func:`directions_to_motion`).

Windows last the paper's T = 34 frames at 15 fps, 2.27 s (``seq_len`` = 45 frames at the feature rate of 20 fps);
the first ``n_seed`` frames (4 at 15 fps, 0.27 s: 5 at 20 fps) of the seed-pose input carry known poses and the
rest are zero with a "known" flag of 0 (the released Yoon et al. / S2AG code's way of feeding "seed poses of length
T"). Inference runs window after window, seeding each with the last ``n_seed`` generated poses.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robogest.learn import require_torch

if TYPE_CHECKING:  # the checker sees torch's own types; at run time a missing torch is one clear error
    import torch
    from torch import nn
    from torch.nn import functional as F
else:
    torch = require_torch("the 's2ag' generator")
    nn = torch.nn
    F = torch.nn.functional

from robogest.errors import InputError
from robogest.generators.learned.s2ag.config import S2AGConfig
from robogest.generators.learned.s2ag.skeleton import (
    BODY_PARTS,
    N_EDGES,
    TEMPORAL_REACH,
    edge_adjacency,
    part_adjacency,
)

#: What the generator returns: edge vectors ``(B, T, 27)``, style ``z`` and its ``mu``, ``logvar`` ``(B, D_s)``
#: (the last two None without a speaker).
GeneratorOutput = tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, torch.Tensor | None]


class STGCNBlock(nn.Module):
    """Spatial graph convolution over a fixed adjacency, then a temporal convolution over ±2 frames (ST-GCN)."""

    adjacency: torch.Tensor  # buffer (V, V)

    def __init__(self, c_in: int, c_out: int, adjacency: np.ndarray) -> None:
        super().__init__()
        a = torch.as_tensor(adjacency, dtype=torch.float32)
        d = a.sum(1).rsqrt()
        self.register_buffer("adjacency", d[:, None] * a * d[None, :])  # (V, V), symmetric normalisation
        self.spatial = nn.Conv2d(c_in, c_out, 1)
        k = 2 * TEMPORAL_REACH + 1
        self.temporal = nn.Conv2d(c_out, c_out, (k, 1), padding=(TEMPORAL_REACH, 0))
        self.residual = nn.Identity() if c_in == c_out else nn.Conv2d(c_in, c_out, 1)
        self.act = nn.LeakyReLU(0.2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C_in, T, V)`` -> ``(B, C_out, T, V)``."""
        y = torch.einsum("bctv,vw->bctw", self.spatial(x), self.adjacency)  # mix neighbouring vertices
        out: torch.Tensor = self.act(self.temporal(self.act(y)) + self.residual(x))
        return out


class AffectiveEncoder(nn.Module):
    """§3.1.4: STGCN over the 9 edges, STGCN over the 3 body parts, 1-D convolutions -> ``(B, T, D_a)``."""

    part_order: torch.Tensor  # buffer (9,): edge indices grouped by body part

    def __init__(self, c_in: int, c: S2AGConfig) -> None:
        super().__init__()
        a1, a2 = edge_adjacency(), part_adjacency()
        self.level1 = nn.Sequential(STGCNBlock(c_in, c.d_aff1, a1), STGCNBlock(c.d_aff1, c.d_aff1, a1))
        self.level2 = STGCNBlock(3 * c.d_aff1, c.d_aff2, a2)
        self.conv = nn.Sequential(
            nn.Conv1d(3 * c.d_aff2, c.d_aff, 3, padding=1), nn.LeakyReLU(0.2), nn.Conv1d(c.d_aff, c.d_aff, 3, padding=1)
        )
        self.register_buffer("part_order", torch.tensor([e for part in BODY_PARTS for e in part]))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` ``(B, T, 9, C_in)`` -> ``(B, T, D_a)``."""
        b, t = x.shape[:2]
        h: torch.Tensor = self.level1(x.permute(0, 3, 1, 2))  # (B, T, 9, C) -> (B, C, T, 9) -> (B, D_a1, T, 9)
        h = h[..., self.part_order].reshape(b, -1, t, 3, 3)  # (B, D_a1, T, part, edge-in-part)
        h = h.permute(0, 1, 4, 2, 3).reshape(b, -1, t, 3)  # (B, D_a1 * 3, T, part): part edges as features
        h = self.level2(h)  # (B, D_a2, T, 3)
        h = h.permute(0, 1, 3, 2).reshape(b, -1, t)  # (B, D_a2 * 3, T)
        out: torch.Tensor = self.conv(h)  # (B, D_a, T)
        return out.transpose(1, 2)  # (B, T, D_a)


class S2AGGeneratorNet(nn.Module):
    """§3.1: four encoders, Bi-GRU with summed directions (eq. 8-9), FC layers to 9 edge vectors (eq. 10)."""

    def __init__(self, c: S2AGConfig) -> None:
        super().__init__()
        self.config = c
        self.mfcc_conv = nn.Sequential(
            nn.Conv1d(c.n_mfcc, c.d_mfcc, 3, padding=1), nn.LeakyReLU(0.2),
            nn.Conv1d(c.d_mfcc, c.d_mfcc, 3, padding=1), nn.LeakyReLU(0.2),
        )  # fmt: skip
        self.mfcc_fc = nn.Linear(c.d_mfcc, c.d_mfcc)
        self.text_conv = nn.Sequential(
            nn.Conv1d(c.n_text, c.d_text, 3, padding=1), nn.LeakyReLU(0.2), nn.Conv1d(c.d_text, c.d_text, 3, padding=1)
        )
        self.speaker_fc = nn.Sequential(nn.Linear(c.n_speakers, c.d_style), nn.LeakyReLU(0.2))
        self.style_mu = nn.Linear(c.d_style, c.d_style)
        self.style_logvar = nn.Linear(c.d_style, c.d_style)
        self.affective = AffectiveEncoder(4, c)  # xyz + "known seed frame" flag
        d_in = c.d_mfcc + c.d_text + c.d_style + c.d_aff
        self.gru = nn.GRU(
            d_in,
            c.d_gen,
            c.gru_layers,
            batch_first=True,
            bidirectional=True,
            dropout=c.dropout if c.gru_layers > 1 else 0,
        )
        self.out = nn.Sequential(
            nn.Linear(c.d_gen, c.d_gen // 2), nn.LeakyReLU(0.2), nn.Linear(c.d_gen // 2, 3 * N_EDGES)
        )

    def style(self, speaker: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Speaker indices ``(B,)`` -> ``(mu, logvar)`` of the style distribution, ``(B, D_s)`` each (eq. 3-4)."""
        h = self.speaker_fc(F.one_hot(speaker, self.config.n_speakers).float())  # (B, S) -> (B, D_s)
        mu: torch.Tensor = self.style_mu(h)
        logvar: torch.Tensor = self.style_logvar(h)
        return mu, logvar

    def forward(
        self,
        mfcc: torch.Tensor,
        text: torch.Tensor,
        seed: torch.Tensor,
        speaker: torch.Tensor | None = None,
        z: torch.Tensor | None = None,
    ) -> GeneratorOutput:
        """Edge vectors of one window.

        Parameters
        ----------
        mfcc : Tensor [shape=(B, T, 37)]
            Normalised MFCC.
        text : Tensor [shape=(B, T, n_text)]
        seed : Tensor [shape=(B, T, 27)]
            Mean-subtracted directions; only the first ``n_seed`` frames are read.
        speaker : Tensor [shape=(B,)], int64, optional
            Style from the speaker's distribution: sampled (reparameterisation) in training mode, its mean in eval.
        z : Tensor [shape=(B, D_s)], optional
            A given style (overrides ``speaker``); neither: the prior mean 0.

        Returns
        -------
        out : Tensor [shape=(B, T, 27)]
            Mean-subtracted edge vectors.
        z, mu, logvar : Tensor [shape=(B, D_s)] (mu, logvar None without ``speaker``)
        """
        c = self.config
        b, t = mfcc.shape[:2]
        mu: torch.Tensor | None = None
        logvar: torch.Tensor | None = None
        if speaker is not None:
            mu, logvar = self.style(speaker)
        if z is None:
            if mu is None or logvar is None:
                z = mfcc.new_zeros(b, c.d_style)
            elif self.training:
                z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()  # reparameterisation trick
            else:
                z = mu
        fm = self.mfcc_fc(self.mfcc_conv(mfcc.transpose(1, 2)).transpose(1, 2))  # (B,37,T) -> (B,D_m,T) -> (B,T,D_m)
        fx = self.text_conv(text.transpose(1, 2)).transpose(1, 2)  # (B, D, T) -> (B, D_x, T) -> (B, T, D_x)
        fs = z[:, None].expand(b, t, c.d_style)  # (B, T, D_s): the style repeated over time
        known = torch.zeros(b, t, N_EDGES, 1, dtype=mfcc.dtype, device=mfcc.device)  # (B, T, 9, 1)
        known[:, : c.n_seed] = 1.0
        s = seed.reshape(b, t, N_EDGES, 3) * known  # (B, T, 27) -> (B, T, 9, 3), unknown frames zeroed
        fa = self.affective(torch.cat([s, known], dim=-1))  # (B, T, 9, 4) -> (B, T, D_a)
        h, _ = self.gru(torch.cat([fm, fx, fs, fa], dim=-1))  # (B, T, 2 * D_e)
        h = h[..., : c.d_gen] + h[..., c.d_gen :]  # eq. 9: forward + backward, (B, T, D_e)
        out: torch.Tensor = self.out(h)  # (B, T, 27)
        return out, z, mu, logvar

    def rollout(self, mfcc: torch.Tensor, text: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Free-running edge vectors over chained windows, as generation runs: window ``k`` covers frames
        ``[k s, k s + T)`` with ``s = T - n_seed``, the first seeded with the mean pose (zeros), each next one with
        the previous window's last ``n_seed`` outputs; no ground truth is read.

        Parameters
        ----------
        mfcc : Tensor [shape=(B, N, 37)]
            Normalised MFCC; ``N = n_seed + k s`` for some ``k >= 1``.
        text : Tensor [shape=(B, N, n_text)]
        z : Tensor [shape=(B, D_s)]
            Style.

        Returns
        -------
        Tensor [shape=(B, N, 27)]
            Mean-subtracted edge vectors: the first window whole, then each next window after its seed frames.
        """
        c = self.config
        step, n = c.seq_len - c.n_seed, mfcc.shape[1]
        if n < c.seq_len or (n - c.n_seed) % step:
            raise InputError(f"s2ag rollout: {n} frames is not n_seed + k * {step} (n_seed = {c.n_seed}, k >= 1)")
        seed = mfcc.new_zeros(mfcc.shape[0], c.seq_len, 3 * N_EDGES)  # the mean pose
        outs = []
        for s in range(0, n - c.n_seed, step):
            out, _, _, _ = self(mfcc[:, s : s + c.seq_len], text[:, s : s + c.seq_len], seed, z=z)  # (B, T, 27)
            outs.append(out if s == 0 else out[:, c.n_seed :])
            seed = F.pad(out[:, -c.n_seed :], (0, 0, 0, c.seq_len - c.n_seed))  # last poses first, rest unread
        return torch.cat(outs, dim=1)  # (B, N, 27)


class S2AGDiscriminator(nn.Module):
    """§3.2: affective encoder, Bi-GRU (summed directions), FC per frame then over time -> one logit."""

    def __init__(self, c: S2AGConfig) -> None:
        super().__init__()
        self.config = c
        self.affective = AffectiveEncoder(3, c)
        self.gru = nn.GRU(
            c.d_aff, c.d_disc, c.gru_layers, batch_first=True, bidirectional=True,
            dropout=c.dropout if c.gru_layers > 1 else 0,
        )  # fmt: skip
        self.per_frame = nn.Linear(c.d_disc, 1)
        self.over_time = nn.Linear(c.seq_len, 1)

    def forward(self, dirs: torch.Tensor) -> torch.Tensor:
        """``(B, T, 27)`` mean-subtracted directions -> ``(B,)`` logits (sigmoid: probability of real)."""
        b, t = dirs.shape[:2]
        h, _ = self.gru(self.affective(dirs.reshape(b, t, N_EDGES, 3)))  # (B, T, 9, 3) -> (B, T, D_a) -> (B,T,2D_d)
        h = h[..., : self.config.d_disc] + h[..., self.config.d_disc :]  # eq. 13, (B, T, D_d)
        logit: torch.Tensor = self.over_time(self.per_frame(h)[..., 0])  # (B, T, 1) -> (B, T) -> (B, 1)
        return logit[:, 0]  # (B,)


class S2AGNet(nn.Module):
    """Generator + discriminator in one module, so one state dict holds the GAN."""

    def __init__(self, config: S2AGConfig) -> None:
        super().__init__()
        self.config = config
        self.generator = S2AGGeneratorNet(config)
        self.discriminator = S2AGDiscriminator(config)

    def forward(self, *args: torch.Tensor | None, **kwargs: torch.Tensor | None) -> GeneratorOutput:
        """The generator's :meth:`S2AGGeneratorNet.forward`."""
        out: GeneratorOutput = self.generator(*args, **kwargs)
        return out
