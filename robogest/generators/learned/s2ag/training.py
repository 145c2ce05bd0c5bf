"""The trainer's view of S2AG (:class:`robogest.learn.spec.ModelSpec` + its GAN methods): losses (eq. 15-17),
windows, optimisers."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.data.datasets import Take, speaker_key
from robogest.data.features import FeatureConfig
from robogest.data.prep import LazyWindows, Normalization, moments, slice_windows
from robogest.generators.learned.s2ag.config import S2AGConfig, mfcc_from_mel
from robogest.generators.learned.s2ag.networks import F, S2AGGeneratorNet, S2AGNet, nn, torch
from robogest.generators.learned.s2ag.skeleton import N_EDGES, expmaps_to_directions
from robogest.learn import config_with_overrides
from robogest.learn.spec import ModelSpec

if TYPE_CHECKING:
    from robogest.learn.trainer import TrainConfig


def split_batch(speech: torch.Tensor, c: S2AGConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A window batch ``(B, T, 37 + n_text + 1)`` -> MFCC ``(B, T, 37)``, text ``(B, T, n_text)``, speaker ``(B,)``."""
    mfcc = speech[..., : c.n_mfcc]
    text = speech[..., c.n_mfcc : c.n_mfcc + c.n_text]
    speaker = speech[:, 0, -1].round().long()  # constant over a window
    return mfcc, text, speaker


def huber(pred: torch.Tensor, target: torch.Tensor, beta: float) -> torch.Tensor:
    """Huber (smooth L1) loss with transition ``beta``, scaled so it is ``|x|`` for large errors."""
    return F.smooth_l1_loss(pred / beta, target / beta) * beta


def kl_divergence(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)), summed over dimensions, batch mean."""
    return (-0.5 * (1 + logvar - mu.pow(2) - logvar.exp()).sum(-1)).mean()


def diversity_regulariser(
    gen: S2AGGeneratorNet,
    mfcc: torch.Tensor,
    text: torch.Tensor,
    poses: torch.Tensor,
    speaker: torch.Tensor,
    out: torch.Tensor,
    z: torch.Tensor,
) -> torch.Tensor:
    """Yoon et al.'s style diversity term: minus motion difference per style difference, for shuffled speakers."""
    perm = torch.randperm(speaker.shape[0], device=speaker.device)
    out2, z2, _, _ = gen(mfcc, text, poses, speaker[perm])
    beta = 0.05
    pose_l1 = (F.smooth_l1_loss(out / beta, out2.detach() / beta, reduction="none") * beta).sum((1, 2))  # (B,)
    z_l1 = (z.detach() - z2.detach()).abs().mean(-1)  # (B,)
    return torch.clamp(-pose_l1 / (z_l1 + 1e-5), min=-1000.0).mean()


class S2AGSpec(ModelSpec[S2AGConfig]):
    """The trainer's view of the model (:class:`robogest.learn.spec.ModelSpec` + its optional GAN methods)."""

    name = "s2ag"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> S2AGConfig:
        config: S2AGConfig = config_with_overrides(
            S2AGConfig, "s2ag", overrides, n_text=n_text, fps=FeatureConfig().fps
        )
        return config

    def config_from_dict(self, d: dict[str, Any]) -> S2AGConfig:
        return S2AGConfig.from_dict(d)

    def fit_config(self, config: S2AGConfig, takes: Sequence[Take]) -> S2AGConfig:
        """Speaker table, MFCC statistics and mean direction from the training takes (one take in memory at a time)."""
        mfcc_mean, mfcc_std = moments(mfcc_from_mel(t.acoustic[:, :64]) for t in takes)  # over ΣT frames, (37,)
        dir_mean, _ = moments(expmaps_to_directions(t.poses).reshape(t.n_frames, -1) for t in takes)  # (27,)
        return dataclasses.replace(
            config,
            speakers=tuple(sorted({speaker_key(t.name) for t in takes})),
            mfcc_mean=tuple(map(float, mfcc_mean)),
            mfcc_std=tuple(map(float, mfcc_std)),
            dir_mean=tuple(map(float, dir_mean)),
        )

    def make_windows(
        self,
        takes: Sequence[Take],
        norm: Normalization | None,
        config: S2AGConfig,
        length: int,
        stride: int,
        store: str | os.PathLike | None = None,
        cache_dir: str | os.PathLike | None = None,
    ) -> tuple[LazyWindows, LazyWindows, np.ndarray]:
        """Windows of ``[normalised MFCC | text | speaker index]`` ``(N, L, 37 + D + 1)`` and mean-subtracted
        directions ``(N, L, 27)`` (``store``: :func:`slice_windows`); the trainer's exp-map normalisation ``norm``
        is not used."""
        table = {s: i for i, s in enumerate(config.speakers)}
        mean, std = np.asarray(config.mfcc_mean, np.float32), np.asarray(config.mfcc_std, np.float32)

        def take_arrays(t: Take) -> tuple[np.ndarray, np.ndarray]:
            mfcc = (mfcc_from_mel(t.acoustic[:, :64]) - mean) / std  # (T, 37)
            spk = np.full((t.n_frames, 1), table.get(speaker_key(t.name), 0), np.float32)  # unseen speaker -> 0
            x = np.concatenate([mfcc, t.text, spk], axis=1)  # (T, 37 + D + 1)
            y = expmaps_to_directions(t.poses).reshape(t.n_frames, -1) - np.asarray(config.dir_mean)  # (T, 27)
            return x, y

        per_take = ((i, *take_arrays(t)) for i, t in enumerate(takes) if t.n_frames >= length)
        return slice_windows(per_take, length, stride, config.n_input, 3 * N_EDGES, store=store)

    def build(self, config: S2AGConfig) -> S2AGNet:
        return S2AGNet(config)

    def sequence_length(self, config: S2AGConfig) -> int:
        return config.seq_len

    def make_optimizers(
        self, model: S2AGNet, train_config: TrainConfig | None, config: S2AGConfig
    ) -> dict[str, torch.optim.Optimizer]:
        """Adam, β = (0.5, 0.999), 5e-4 for the generator and 1e-4 for the discriminator (§4)."""
        betas = (config.beta1, 0.999)
        return {
            "generator": torch.optim.Adam(model.generator.parameters(), lr=config.lr_generator, betas=betas),
            "discriminator": torch.optim.Adam(
                model.discriminator.parameters(), lr=config.lr_discriminator, betas=betas
            ),
        }

    def loss(
        self, model: nn.Module, speech: torch.Tensor, poses: torch.Tensor, epoch: int, config: S2AGConfig
    ) -> torch.Tensor:
        """Huber reconstruction of the edge vectors, each window seeded with its true first poses (teacher-forced)."""
        gen = _unwrap(model).generator
        mfcc, text, speaker = split_batch(speech, config)
        out, _, _, _ = gen(mfcc, text, poses, speaker)
        return huber(out, poses, config.huber_beta)

    def validation_length(self, config: S2AGConfig) -> int:
        """Held-out sequences span :attr:`S2AGConfig.val_windows` chained windows (6.25 s by default)."""
        return config.validation_length

    def validation_loss(
        self, model: nn.Module, speech: torch.Tensor, poses: torch.Tensor, epoch: int, config: S2AGConfig
    ) -> torch.Tensor:
        """Huber loss of a free-running rollout (:meth:`S2AGGeneratorNet.rollout`), what ``best.pt`` is chosen on.

        As :class:`S2AGGenerator` generates: the first window seeded with the mean pose, each next one with the
        model's own last poses, the speaker's mean style; the ground truth is only the target. (The teacher-forced
        :meth:`loss` seeds every window with true poses and so never sees the model's own drift.)
        """
        gen = _unwrap(model).generator
        mfcc, text, speaker = split_batch(speech, config)
        z, _ = gen.style(speaker)  # the style's mean, as generate(speaker=k)
        return huber(gen.rollout(mfcc, text, z), poses, config.huber_beta)

    def discriminator_step(
        self, model: nn.Module, opt: torch.optim.Optimizer, fake: torch.Tensor, real: torch.Tensor
    ) -> float:
        """One D update on generated ``fake`` and ``real`` ``(B, T, 27)``; eq. 16 as binary cross-entropy."""
        disc = _unwrap(model).discriminator
        lr, lf = disc(real), disc(fake.detach())
        loss = F.binary_cross_entropy_with_logits(lr, torch.ones_like(lr)) + F.binary_cross_entropy_with_logits(
            lf, torch.zeros_like(lf)
        )
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return float(loss.detach())

    def generator_step(
        self,
        model: nn.Module,
        opt: torch.optim.Optimizer,
        speech: torch.Tensor,
        poses: torch.Tensor,
        config: S2AGConfig,
    ) -> dict[str, float]:
        """One G update with eq. 15 (discriminator weights untouched: only G's optimiser steps)."""
        net = _unwrap(model)
        gen, disc = net.generator, net.discriminator
        mfcc, text, speaker = split_batch(speech, config)
        out, z, mu, logvar = gen(mfcc, text, poses, speaker)
        rec = huber(out, poses, config.huber_beta)
        lf = disc(out)
        adv = F.binary_cross_entropy_with_logits(lf, torch.ones_like(lf))  # eq. 17: -log D(G)
        div = diversity_regulariser(gen, mfcc, text, poses, speaker, out, z)
        kld = kl_divergence(mu, logvar)
        total = config.w_huber * rec + config.w_gan * adv + config.w_div * div + config.w_kld * kld
        opt.zero_grad(set_to_none=True)
        total.backward()
        opt.step()
        return {"huber": float(rec.detach()), "g_adv": float(adv.detach()), "div": float(div.detach()),
                "kld": float(kld.detach()), "g_total": float(total.detach())}  # fmt: skip

    def train_step(
        self,
        model: nn.Module,
        optimizers: dict[str, torch.optim.Optimizer],
        speech: torch.Tensor,
        poses: torch.Tensor,
        epoch: int,
        config: S2AGConfig,
    ) -> dict[str, float]:
        """A discriminator step (eq. 16) on gestures generated for this batch, then the generator step (eq. 15)
        against the updated discriminator: the order of the authors' code (``forward_pass_s2ag``: "train D",
        then "train G" on a new generator pass)."""
        gen = _unwrap(model).generator
        mfcc, text, speaker = split_batch(speech, config)
        with torch.no_grad():
            fake = gen(mfcc, text, poses, speaker)[0]  # (B, T, 27), no graph: only D learns from it
        d_loss = self.discriminator_step(model, optimizers["discriminator"], fake, poses)
        g = self.generator_step(model, optimizers["generator"], speech, poses, config)
        g["d_loss"] = d_loss
        g["loss"] = g["huber"]
        return g


def _unwrap(model: nn.Module) -> S2AGNet:
    """The S2AG network itself, also when DDP wraps it (as ``.module``)."""
    inner = model.module if hasattr(model, "module") else model
    if not isinstance(inner, S2AGNet):
        raise TypeError(f"the s2ag trainer needs an S2AGNet (or one wrapped by DDP), got {type(inner).__name__}")
    return inner


SPEC = S2AGSpec()
