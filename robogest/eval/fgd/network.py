"""The BEAT2/EMAGE FGD evaluator network (``VAESKConv``) in plain torch, with the official state-dict layout.

Only the encoder is used for FGD; the decoder and the (unused, non-variational) ``fc_mu``/``fc_logvar`` layers
exist so that the official ``AESKConv_240_100.bin`` loads key for key. Parameter and buffer names follow the
published file (``encoder.layers.{i}.0.residual.0.weight`` ...), so changing a module attribute here breaks
loading; ``tests/eval/test_fgd.py`` pins every key and shape.

This module imports torch at import time: import it only when FGD is asked for.
"""

from __future__ import annotations

import itertools

import torch
from torch import nn
from torch.nn import functional as F

from robogest.eval.fgd.topology import (
    GROUPS,
    INPUT_DIM,
    KERNEL,
    LATENT_DIM,
    N_LAYERS,
    LayerPlan,
    conv_mask,
    encoder_plan,
    pool_matrix,
)


class SkeletonConv(nn.Module):
    """Temporal 1-D convolution whose weight is masked so that each edge's outputs see only neighbouring edges.

    Input and output ``[shape=(B, C, T)]``, channels grouped per edge.
    """

    mask: torch.Tensor  # buffer (C_out, C_in, kernel), {0, 1}

    def __init__(self, layer: LayerPlan, kernel: int, stride: int, padding: int) -> None:
        super().__init__()
        mask = torch.from_numpy(conv_mask(layer, kernel))
        self.weight = nn.Parameter(torch.empty_like(mask))
        self.bias = nn.Parameter(torch.zeros(layer.out_channels))
        self.register_buffer("mask", mask)
        self.stride, self.padding = stride, padding
        nn.init.kaiming_uniform_(self.weight, a=5**0.5)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.pad(x, (self.padding, self.padding))  # zeros at both ends of the sequence
        return F.conv1d(x, self.weight * self.mask, self.bias, stride=self.stride)


class SkeletonPool(nn.Module):
    """Averages groups of edges (a fixed matrix, stored in the state dict as ``weight``)."""

    weight: torch.Tensor  # buffer (C_pooled, C_in)

    def __init__(self, layer: LayerPlan) -> None:
        super().__init__()
        self.register_buffer("weight", torch.from_numpy(pool_matrix(layer)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.matmul(self.weight, x)


class SkeletonResidual(nn.Module):
    """One encoder layer: (masked conv, stride 2 -> GroupNorm) + masked 1x1 shortcut, then pooling and tanh.

    ``[shape=(B, C_in, T)]`` -> ``[shape=(B, C_pooled, T / 2)]``.
    """

    def __init__(self, layer: LayerPlan) -> None:
        super().__init__()
        self.residual = nn.Sequential(
            SkeletonConv(layer, KERNEL, stride=2, padding=(KERNEL - 1) // 2), nn.GroupNorm(GROUPS, layer.out_channels)
        )
        self.shortcut = SkeletonConv(layer, 1, stride=2, padding=0)
        self.common = nn.Sequential(*([SkeletonPool(layer)] if layer.pools else []), nn.Tanh())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y: torch.Tensor = self.common(self.residual(x) + self.shortcut(x))
        return y


class SkeletonEncoder(nn.Module):
    """Rot6d motion ``[shape=(B, T, 330)]`` -> latent frames ``[shape=(B, T / 16, 240)]``."""

    def __init__(self) -> None:
        super().__init__()
        self.layers = nn.ModuleList(nn.Sequential(SkeletonResidual(layer)) for layer in encoder_plan())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x.permute(0, 2, 1)
        for layer in self.layers:
            y = layer(y)  # (B, C, T) with C and T of that layer
        return y.permute(0, 2, 1)


class _ResBlock(nn.Module):
    def __init__(self, channels: int) -> None:
        super().__init__()
        self.model = nn.Sequential(
            nn.Conv1d(channels, channels, 3, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv1d(channels, channels, 3, padding=1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y: torch.Tensor = self.model(x)
        return x + y


class ConvDecoder(nn.Module):
    """Latent frames ``[shape=(B, T', 240)]`` -> rot6d motion ``[shape=(B, 16 T', 330)]`` (not used by FGD)."""

    def __init__(self) -> None:
        super().__init__()
        channels = [LATENT_DIM] * N_LAYERS + [INPUT_DIM]
        layers: list[nn.Module] = [_ResBlock(LATENT_DIM), _ResBlock(LATENT_DIM)]
        for c_in, c_out in itertools.pairwise(channels):
            layers += [nn.Upsample(scale_factor=2, mode="nearest"), nn.Conv1d(c_in, c_out, 3, padding=1)]
            layers.append(nn.LeakyReLU(0.2))
        layers.append(nn.Conv1d(INPUT_DIM, INPUT_DIM, 3, padding=1))
        self.main = nn.Sequential(*layers)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        y: torch.Tensor = self.main(z.permute(0, 2, 1))
        return y.permute(0, 2, 1)


class MotionAutoencoder(nn.Module):
    """EMAGE's ``VAESKConv`` evaluator: skeleton-aware encoder + convolutional decoder, latent 240 per 16 frames."""

    def __init__(self) -> None:
        super().__init__()
        self.fc_mu = nn.Linear(LATENT_DIM, LATENT_DIM)  # unused: the published evaluator is not variational
        self.fc_logvar = nn.Linear(LATENT_DIM, LATENT_DIM)
        self.encoder = SkeletonEncoder()
        self.decoder = ConvDecoder()

    def encode(self, rot6d: torch.Tensor) -> torch.Tensor:
        """``[shape=(B, T, 330)]`` (T a multiple of 16) -> ``[shape=(B, T / 16, 240)]`` latent features."""
        z: torch.Tensor = self.encoder(rot6d)
        return z

    def forward(self, rot6d: torch.Tensor) -> torch.Tensor:
        y: torch.Tensor = self.decoder(self.encoder(rot6d))
        return y
