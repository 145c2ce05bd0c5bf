"""Rhythmic Gesticulator (Ao et al., SIGGRAPH Asia 2022, §4-6): beat-normalised blocks, gesture lexicon, interpreters.

Importing this module needs PyTorch; register the generator through a lazy factory.

Data (§4.2, :mod:`robogest.data.blocks`, :func:`take_blocks`): speech and motion are cut at beats and every clip is
time-scaled to a block of ``K = D_M * fps`` frames (10 at 0.5 s, 20 fps): motion and text by resampling, audio by
pitch-preserving time-scale modification of the waveform (librosa's phase vocoder) with the log-mel recomputed on the
stretched audio. Generated blocks are time-scaled back to their clips' exact frame counts and Gaussian-smoothed
(kernel 5).

Parts, one :class:`RhythmicNet`:

* audio encoder (§4.1.3): 1-D convolutions over the block's log-mel (vq-wav2vec cannot be downloaded);
  ``a_low`` = layer 2, ``a_high`` = last layer, trained with the contrastive loss of eq. 1 (text as anchor).
  Swappable through :data:`AUDIO_ENCODERS`.
* gesture lexicon (§5.1): VQ-VAE over motion blocks (4 conv layers + FC, mirrored decoder, eq. 3, w_α = w_β = 1).
* generator (§5.2-5.3): previous block's motion features (3-layer conv ``E_M``), three consecutive ``a_low``
  blocks (one FC ``E_A``), lexeme, style code, positional encoding (eq. 8) -> MLP encoder -> H groups of C-way
  Gumbel-softmax latent -> LSTM decoder. Losses: reconstruction, perceptual (0.5), lexeme (0.2), style KL (1.0).
* interpreters (§6.1-6.3): lexeme classifier from ``a_high``, text and the previous lexeme; style regressor from
  ``a_low``; each with an audio-only twin.
* silent-period hint (§6.4.1): lexemes mostly seen on silent blocks are the silent lexemes; silent blocks get
  the silent lexeme nearest the current (training) or previous (inference) one; ~5 % silent blocks are added to
  the generator's training batch. A silent block has no words and, in takes without any words, mostly quiet frames
  (:func:`robogest.data.blocks.silent_blocks`), so takes without transcripts train the hint too.

Beats: training takes and run-time speech are cut by one rule, :func:`take_rhythm` (the speech module's
``identify_beats`` on the whole take's standardised log-mel, :func:`robogest.data.blocks.frame_beats`), and turned
into blocks by one function, :func:`take_blocks`. ``Speech.beats_s`` (found on the waveform) is not used, since
cached training takes keep only their features.

Training through :func:`robogest.learn.trainer.train`: :meth:`RhythmicSpec.make_windows` cuts every take into
blocks once and hands the trainer windows of ``window_blocks`` consecutive blocks. The paper's stages run one after
another (``stages="sequential"``, the default): audio-encoder pre-training, lexicon, generator, interpreters, each
for its share of ``--epochs`` (:meth:`RhythmicSpec.plan_epochs`), every earlier stage frozen. ``stages="joint"``
trains all four at once, each only by its own objective (downstream parts read detached outputs of upstream ones).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from robogest.learn import require_torch

torch = require_torch("the 'rhythmic' generator")
nn = torch.nn
F = torch.nn.functional

from robogest.data.blocks import (  # noqa: E402
    block_frames,
    clip_bounds,
    denormalize_blocks,
    frame_beats,
    gaussian_smooth,
    normalize_clips,
    quiet_frames,
    silent_blocks,
    tsm_mel_blocks,
)
from robogest.data.features import FeatureConfig, expmap_to_motion, speech_inputs  # noqa: E402
from robogest.data.prep import Normalization, slice_windows  # noqa: E402
from robogest.errors import InputError  # noqa: E402
from robogest.generators.learned import CheckpointGenerator  # noqa: E402
from robogest.learn import config_with_overrides  # noqa: E402
from robogest.motion.human_motion import HumanMotion  # noqa: E402
from robogest.speech.types import Speech  # noqa: E402

#: Text features are divided by this inside the model, so the silence vector (-15, §3.2) becomes -1.
TEXT_SCALE = 15.0


#: Share of inserted silent blocks that are not the first of their run: with run lengths uniform in 0-10 (§6.4.1),
#: 5 blocks per run on average of which 10/11 are firsts, (5 - 10/11) / 5 = 0.82.
SILENT_RUN_LATER = 0.82

#: Training stages in the paper's order (§4.1.3, §5.1, §5.3, §6).
STAGES = ("encoder", "lexicon", "generator", "interpreters")
#: The objective of each stage, as named in :attr:`RhythmicNet.last_parts`.
STAGE_LOSSES = ("contrastive", "vq", "gen", "interp")


@dataclass(frozen=True)
class RhythmicConfig:
    """Hyper-parameters; the defaults are the paper's values (§7.1.2) where it gives them.

    Attributes
    ----------
    n_acoustic, n_text, n_pose : int
        Frame inputs (64 log-mel + 5 timing), text features, pose values (17 joints x 3 exp-map).
    n_mels : int
        Leading acoustic columns that are log-mel bands (the audio encoder's input; timing features are unused).
    fps, min_beat_gap_s, max_beat_gap_s : float
        Frame rate and D_m, D_M (§4.2.1); ``K = round(D_M * fps)``.
    audio_tsm : bool
        Audio blocks from time-scaled audio with the log-mel recomputed (§4.2.2); False, or a take without its
        recording, resamples the log-mel frames instead.
    audio_sr, mel_window_s : int, float
        Sample rate (Hz) and mel window (s) of that analysis: the speech front-end's (``SpeechConfig``) values.
    window_blocks : int
        Consecutive blocks per training window (8, about 4 s: "the generator synthesizes 4 seconds of gestures at a
        time"); the first and last serve as context only.
    stages : {"sequential", "joint"}
        Train the four :data:`STAGES` one after another (the paper) or all at once.
    stage_weights : tuple of 4 float
        Shares of the epochs given to each stage when sequential (each stage gets at least one epoch).
    stage_ends : tuple of int
        Epoch (exclusive, 0-based) at which each stage ends; filled in by :meth:`RhythmicSpec.plan_epochs` from
        ``--epochs`` and kept in the checkpoint (a resumed run with more epochs trains the interpreters longer).
    audio_encoder : {"conv", "mel"}
        :data:`AUDIO_ENCODERS` entry; ``audio_channels``, ``audio_layers`` (vq-wav2vec: 8), ``low_layer``
        (1-based; the paper's a_low is layer 2) configure it.
    contrast_dim, temperature : int, float
        Projection size and τ of eq. 1.
    lexicon_size, lexeme_dim, vq_channels : int
        Number of lexemes N_s (paper: 50), lexeme vector size d_s (192), VQ-VAE conv channels.
    motion_feat_dim, audio_feat_dim, style_dim, pe_dim, hidden : int
        d_m~ (128), d_a~ (128), d_z (32), d_P (32), and the MLP/LSTM width, which the paper does not give (128, like
        its other widths; 256 costs a third of the CPU speed: 18x instead of 27x real time).
    latent_groups, latent_classes, latent_group_dim : int
        H groups of C-way Gumbel-softmax categories (paper: H = 64, C = 128) and each category vector's size.
    gumbel_tau : float
    lr : float
        Adam learning rate (3e-4, §7.1.2), used when ``robogest train --lr`` is not given.
    w_rec, w_perc, w_lexeme, w_z, w_alpha, w_beta : float
        Loss weights of eq. 9 and eq. 3.
    silent_augment : float
        Share of generator training blocks that are inserted silent blocks (§6.4.1: 5 %).
    silent_share : float
        A lexeme is silent when at least this share of its blocks are silent blocks.
    quiet_share : float
        In a take (or speech) without any words, a word-free block is silent when more than this share of its
        frames are quiet (:func:`robogest.data.blocks.silent_blocks`).
    lexeme_temperature : float
        :meth:`RhythmicGenerator.generate` samples each lexeme from the interpreter's softmax at this temperature
        with a generator seeded by ``seed`` (0: always the most likely lexeme, so ``seed`` has no effect).
    smooth_kernel : int
        Gaussian kernel (frames) applied to the denormalised output.
    """

    n_acoustic: int = 69
    n_text: int = 384
    n_pose: int = 51
    n_mels: int = 64
    fps: float = 20.0
    min_beat_gap_s: float = 0.2
    max_beat_gap_s: float = 0.5
    audio_tsm: bool = True
    audio_sr: int = 16000
    mel_window_s: float = 0.1
    window_blocks: int = 8
    stages: str = "sequential"
    stage_weights: tuple = (1.0, 2.0, 4.0, 3.0)
    stage_ends: tuple = ()
    audio_encoder: str = "conv"
    audio_channels: int = 128
    audio_layers: int = 8
    low_layer: int = 2
    contrast_dim: int = 64
    temperature: float = 0.1
    lexicon_size: int = 50
    lexeme_dim: int = 192
    vq_channels: int = 128
    motion_feat_dim: int = 128
    audio_feat_dim: int = 128
    style_dim: int = 32
    pe_dim: int = 32
    hidden: int = 128
    latent_groups: int = 64
    latent_classes: int = 128
    latent_group_dim: int = 8
    gumbel_tau: float = 1.0
    lr: float = 3e-4
    w_rec: float = 1.0
    w_perc: float = 0.5
    w_lexeme: float = 0.2
    w_z: float = 1.0
    w_alpha: float = 1.0
    w_beta: float = 1.0
    silent_augment: float = 0.05
    silent_share: float = 0.5
    quiet_share: float = 0.5
    lexeme_temperature: float = 1.0
    smooth_kernel: int = 5

    def __post_init__(self) -> None:
        if self.stages not in ("sequential", "joint"):
            raise InputError(f"rhythmic option stages={self.stages!r}: choose 'sequential' or 'joint'")
        if len(self.stage_weights) != len(STAGES) or min(self.stage_weights) < 0 or min(self.stage_weights[1:]) <= 0:
            raise InputError(
                f"rhythmic option stage_weights={list(self.stage_weights)}: needs {len(STAGES)} numbers, the encoder's "
                ">= 0 (0 skips its pre-training) and the others > 0"
            )
        if self.window_blocks < 3:
            raise InputError("rhythmic option window_blocks must be >= 3 (a block and its two neighbours)")

    @property
    def block(self) -> int:
        return block_frames(self.max_beat_gap_s, self.fps)

    def stage_at(self, epoch: int) -> str | None:
        """The stage trained at ``epoch`` (0-based); None: all at once (joint, or no plan yet)."""
        if self.stages == "joint" or not self.stage_ends:
            return None
        for name, end in zip(STAGES, self.stage_ends, strict=True):
            if epoch < end:
                return name
        return STAGES[-1]

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RhythmicConfig:
        d = dict(d)
        for k in ("stage_weights", "stage_ends"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)


# --------------------------------------------------------------------------------------------------- audio encoder
class ConvAudioEncoder(nn.Module):
    """Stack of ``audio_layers`` 1-D convolutions (kernel 3) over the log-mel block; every layer's output is kept."""

    trainable = True

    def __init__(self, c: RhythmicConfig) -> None:
        super().__init__()
        chans = [c.n_mels] + [c.audio_channels] * c.audio_layers
        self.layers = nn.ModuleList(
            nn.Sequential(nn.Conv1d(i, o, 3, padding=1), nn.LeakyReLU(0.2)) for i, o in itertools.pairwise(chans)
        )
        self.layer_dims = chans[1:]

    def forward(self, mel):
        """``mel`` ``(B, K, n_mels)`` -> list of ``(B, K, C_l)``, one per layer (``l = 1..L``)."""
        h = mel.transpose(1, 2)  # (B, n_mels, K)
        out = []
        for layer in self.layers:
            h = layer(h)  # (B, C, K)
            out.append(h.transpose(1, 2))  # (B, K, C)
        return out


class MelAudioEncoder(nn.Module):
    """Parameter-free stand-in: ``a_low = a_high =`` the standardised log-mel (no contrastive pre-training)."""

    trainable = False

    def __init__(self, c: RhythmicConfig) -> None:
        super().__init__()
        self.layer_dims = [c.n_mels]

    def forward(self, mel):
        return [mel]


#: Audio encoders by name: ``cls(config)`` with ``layer_dims``, ``trainable`` (has a pre-training stage) and
#: ``forward(mel) -> [per-layer (B, K, C_l)]``.
AUDIO_ENCODERS: dict[str, type] = {"conv": ConvAudioEncoder, "mel": MelAudioEncoder}


# --------------------------------------------------------------------------------------------------- lexicon
class MotionVQ(nn.Module):
    """VQ-VAE of §5.1: 4 conv layers + FC -> lexeme space (d_s), codebook of ``lexicon_size``, mirrored decoder."""

    def __init__(self, c: RhythmicConfig) -> None:
        super().__init__()
        k, ch = c.block, c.vq_channels
        self.k, self.ch = k, ch
        self.cfg_alpha, self.cfg_beta = c.w_alpha, c.w_beta
        convs = []
        for i in range(4):
            convs += [nn.Conv1d(c.n_pose if i == 0 else ch, ch, 3, padding=1), nn.LeakyReLU(0.2)]
        self.enc = nn.Sequential(*convs, nn.Flatten(), nn.Linear(ch * k, c.lexeme_dim))
        self.dec_fc = nn.Linear(c.lexeme_dim, ch * k)
        dec = []
        for i in range(4):
            dec += [nn.LeakyReLU(0.2), nn.Conv1d(ch, c.n_pose if i == 3 else ch, 3, padding=1)]
        self.dec = nn.Sequential(*dec)
        self.codebook = nn.Parameter(torch.randn(c.lexicon_size, c.lexeme_dim) * 0.1)
        self.register_buffer("usage", torch.ones(c.lexicon_size))  # EMA of how often each code is picked
        self.register_buffer("initialised", torch.zeros((), dtype=torch.bool))

    def encode(self, m, frozen: bool = False):
        """Motion blocks ``(B, K, P)`` -> ``E(M)`` ``(B, d_s)``; ``frozen``: through detached weights (no update)."""
        x = m.transpose(1, 2)  # (B, P, K)
        if not frozen:
            return self.enc(x)
        params = {n: p.detach() for n, p in self.enc.named_parameters()}
        return torch.func.functional_call(self.enc, params, (x,))

    def decode(self, s):
        """``(B, d_s)`` -> ``(B, K, P)``."""
        h = self.dec_fc(s).view(s.shape[0], self.ch, self.k)  # (B, ch * K) -> (B, ch, K)
        return self.dec(h).transpose(1, 2)  # (B, P, K) -> (B, K, P)

    def quantize(self, e):
        """Nearest codebook entries (eq. 4): indices ``(B,)``."""
        return torch.cdist(e, self.codebook.detach()).argmin(dim=1)

    def forward(self, m):
        """Eq. 3 loss, reconstruction error and indices of motion blocks ``(B, K, P)``."""
        e = self.encode(m)  # (B, d_s)
        if self.training:
            self._maintain(e.detach())
        idx = self.quantize(e)
        s = self.codebook[idx]  # (B, d_s)
        rec = self.decode(e + (s - e).detach())  # straight-through gradient to the encoder
        rec_err = F.mse_loss(rec, m)
        loss = rec_err + self.cfg_alpha * F.mse_loss(e, s.detach()) + self.cfg_beta * F.mse_loss(e.detach(), s)
        return loss, rec_err.detach(), idx

    @torch.no_grad()
    def _maintain(self, e) -> None:
        """Data-dependent start and dead-code restart, so the small lexicon is actually used (not in eq. 3)."""
        n = self.codebook.shape[0]
        if not bool(self.initialised):
            pick = torch.randint(0, e.shape[0], (n,), device=e.device)
            self.codebook.data.copy_(e[pick] + 0.01 * torch.randn_like(e[pick]))
            self.initialised.fill_(True)
        idx = self.quantize(e)
        hist = torch.bincount(idx, minlength=n).float() / max(e.shape[0], 1)
        self.usage.mul_(0.95).add_(0.05 * hist * n)
        dead = self.usage < 0.02
        if dead.any():
            pick = torch.randint(0, e.shape[0], (int(dead.sum()),), device=e.device)
            self.codebook.data[dead] = e[pick] + 0.01 * torch.randn_like(e[pick])
            self.usage[dead] = 1.0


# --------------------------------------------------------------------------------------------------- generator
def positional_encoding(k: int, d: int) -> np.ndarray:
    """Eq. 8 over the ``k`` frames of a block: ``p_j[2i] = sin(j / β^(2i/d))``, ``p_j[2i+1] = cos(...)``, β = 1e4.

    (The paper prints ``K`` in the numerator; the frame index ``j`` is what lets the generator know its progress.)
    Returns ``(k, d)``.
    """
    j = np.arange(k)[:, None]
    i = np.arange(0, d, 2)[None, :]
    ang = j / 10000.0 ** (i / d)  # (k, ceil(d / 2))
    p = np.zeros((k, d), np.float32)
    p[:, 0::2] = np.sin(ang)
    p[:, 1::2] = np.cos(ang[:, : d // 2])
    return p


def _conv_stack(c_in: int, c_hid: int, c_out: int, n: int) -> nn.Sequential:
    chans = [c_in] + [c_hid] * (n - 1) + [c_out]
    layers = []
    for a, b in itertools.pairwise(chans):
        layers += [nn.Conv1d(a, b, 3, padding=1), nn.LeakyReLU(0.2)]
    return nn.Sequential(*layers[:-1])


class BlockGenerator(nn.Module):
    """G of eq. 5: MLP encoder -> H x C Gumbel-softmax latent -> LSTM decoder, one motion block at a time."""

    def __init__(self, c: RhythmicConfig, low_dim: int) -> None:
        super().__init__()
        self.c = c
        self.e_m = _conv_stack(c.n_pose, c.hidden, c.motion_feat_dim, 3)  # E_M, 3 conv layers (eq. 6)
        self.e_a = nn.Linear(3 * low_dim, c.audio_feat_dim)  # E_A, one FC layer (eq. 7)
        self.style = nn.Sequential(_conv_stack(c.n_pose, c.hidden, c.style_dim, 2))  # amortised style code z_i
        self.register_buffer("pe", torch.from_numpy(positional_encoding(c.block, c.pe_dim)))
        n_in = c.motion_feat_dim + c.audio_feat_dim + c.lexeme_dim + c.style_dim + c.pe_dim
        self.mlp = nn.Sequential(
            nn.Linear(n_in, c.hidden), nn.LeakyReLU(0.2), nn.Linear(c.hidden, c.latent_groups * c.latent_classes)
        )
        self.latent = nn.Parameter(torch.randn(c.latent_groups, c.latent_classes, c.latent_group_dim) * 0.5)
        self.lstm = nn.LSTM(c.latent_groups * c.latent_group_dim + c.motion_feat_dim, c.hidden, batch_first=True)
        self.out = nn.Linear(c.hidden, c.n_pose)

    def style_code(self, m):
        """Per-block style code ``(B, d_z)`` of motion blocks ``(B, K, P)`` (stands in for one free z per block)."""
        return self.style(m.transpose(1, 2)).mean(dim=2)  # (B, d_z, K) -> (B, d_z)

    def forward(self, prev, a_low3, s, z):
        """One block.

        Parameters
        ----------
        prev : Tensor [shape=(B, K, P)]
            Previous (normalised) motion block.
        a_low3 : Tensor [shape=(B, K, 3 * d_a)]
            ``a_low`` of blocks i-1, i, i+1 side by side.
        s : Tensor [shape=(B, d_s)]
            Lexeme vector.
        z : Tensor [shape=(B, d_z)]

        Returns
        -------
        Tensor [shape=(B, K, P)]
        """
        c = self.c
        b, k = prev.shape[0], c.block
        m_feat = self.e_m(prev.transpose(1, 2)).transpose(1, 2)  # (B, P, K) -> (B, d_m, K) -> (B, K, d_m)
        cond = torch.cat(
            [m_feat, self.e_a(a_low3), s[:, None].expand(b, k, -1), z[:, None].expand(b, k, -1),
             self.pe[None].expand(b, k, -1)], dim=2,
        )  # fmt: skip  # (B, K, n_in)
        logits = self.mlp(cond).view(b, k, c.latent_groups, c.latent_classes)  # (B, K, H * C) -> (B, K, H, C)
        if self.training:
            w = F.gumbel_softmax(logits, tau=c.gumbel_tau, hard=True, dim=-1)  # one-hot forward, as at run time
            q = torch.einsum("bkhc,hcd->bkhd", w, self.latent)  # (B, K, H, d_g)
        else:  # the most likely category's vector: a gather, not a product with a one-hot
            groups = torch.arange(c.latent_groups, device=logits.device)
            q = self.latent[groups, logits.argmax(-1)]  # (H,), (B, K, H) -> (B, K, H, d_g)
        q = q.reshape(b, k, -1)  # (B, K, H, d_g) -> (B, K, H * d_g)
        h, _ = self.lstm(torch.cat([q, m_feat], dim=2))  # (B, K, hidden)
        return self.out(h)  # (B, K, P)


# --------------------------------------------------------------------------------------------------- interpreters
class Interpreter(nn.Module):
    """LSTM over a block's condition frames -> last state -> head (lexeme logits or style code, §6.1-6.2).

    ``with_text=False`` is the audio-only variant (§6.3): the text branch is absent.
    """

    def __init__(self, c: RhythmicConfig, audio_dim: int, ctx_dim: int, n_out: int, with_text: bool) -> None:
        super().__init__()
        self.with_text = with_text
        self.e_a = nn.Linear(3 * audio_dim, c.audio_feat_dim)  # E_A^lex / E_A^style: one FC layer
        self.e_t = nn.Linear(c.n_text, c.audio_feat_dim) if with_text else None  # E_T: one FC layer
        n_in = c.audio_feat_dim * (2 if with_text else 1) + ctx_dim
        self.lstm = nn.LSTM(n_in, c.hidden, batch_first=True)
        self.head = nn.Linear(c.hidden, n_out)

    def forward(self, audio3, text, ctx):
        """``audio3`` ``(B, K, 3 * d)``, ``text`` ``(B, K, D)`` (ignored audio-only), ``ctx`` ``(B, d_ctx)``."""
        b, k = audio3.shape[:2]
        parts = [self.e_a(audio3)]
        if self.e_t is not None:
            parts.append(self.e_t(text))
        parts.append(ctx[:, None].expand(b, k, -1))
        h, _ = self.lstm(torch.cat(parts, dim=2))  # (B, K, hidden)
        return self.head(h[:, -1])  # (B, n_out)


# --------------------------------------------------------------------------------------------------- beat rhythm
def take_rhythm(
    mel: np.ndarray, mel_db: np.ndarray, text: np.ndarray, c: RhythmicConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Clip bounds and silent clips of a whole take or speech: the one rule of training and inference.

    Parameters
    ----------
    mel : ndarray [shape=(T, n_mels)]
        Standardised log-mel (``Normalization.acoustic`` of the take's or speech's acoustic features).
    mel_db : ndarray [shape=(T, n_mels)]
        The same log-mel before standardisation, dB (for :func:`robogest.data.blocks.quiet_frames`).
    text : ndarray [shape=(T, D)]
        Raw text features (frames outside words are the silence vector, -15).
    c : RhythmicConfig

    Returns
    -------
    bounds : ndarray [shape=(C + 1,)], int
        From beats by :func:`robogest.data.blocks.frame_beats` (which applies the speech module's
        :func:`~robogest.speech.beats.identify_beats`) on ``mel``.
    silent : ndarray [shape=(C,)], bool
        :func:`robogest.data.blocks.silent_blocks` (words from ``text``, quiet frames from ``mel_db``).
    """
    beats = frame_beats(mel, c.fps, c.min_beat_gap_s, c.max_beat_gap_s)
    bounds = clip_bounds(beats, mel.shape[0], c.fps)
    silent = silent_blocks(bounds, word_frames(text), quiet_frames(mel_db), c.quiet_share)
    return bounds, silent


def word_frames(text: np.ndarray) -> np.ndarray:
    """Frames ``(T,)`` inside a word: text features other than the silence vector (raw scale, -15)."""
    return ~np.all(text <= -TEXT_SCALE + 1e-3, axis=1)


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
        audio blocks are time-scaled audio re-analysed (:func:`robogest.data.blocks.tsm_mel_blocks`); without it the
        log-mel frames are resampled.
    poses : ndarray [shape=(T, P)], radians, optional
        Exponential maps (a training take), returned normalised and in blocks.
    """
    m = c.n_mels
    mean, std = norm.acoustic_mean[:m], norm.acoustic_std[:m]
    mel = ((mel_db - mean) / std).astype(np.float32)  # (T, M) standardised
    bounds, silent = take_rhythm(mel, mel_db, text, c)
    k = c.block
    if audio is not None and c.audio_tsm:
        mel_blocks = (tsm_mel_blocks(audio, c.audio_sr, bounds, c.fps, k, m, c.mel_window_s) - mean) / std
    else:
        mel_blocks = normalize_clips(mel, bounds, k)
    pose_blocks = normalize_clips(norm.pose(poses), bounds, k) if poses is not None else None
    return TakeBlocks(bounds, silent, mel_blocks.astype(np.float32), normalize_clips(text, bounds, k), pose_blocks)


# --------------------------------------------------------------------------------------------------- whole model
@dataclass
class Blocks:
    """The blocks of a batch of training windows (tensors) and the training samples among them.

    ``mel`` ``(N, K, n_mels)``, ``text`` ``(N, K, D)`` (scaled: silence = -1), ``poses`` ``(N, K, P)``, ``empty``
    ``(N,)`` bool (silent block: :func:`~robogest.data.blocks.silent_blocks`); ``prev``, ``cur``, ``nxt`` ``(S,)``
    block indices of the samples (every block but a window's first and last, which serve as context).
    """

    mel: Any
    text: Any
    poses: Any
    empty: Any
    prev: Any
    cur: Any
    nxt: Any


class RhythmicNet(nn.Module):
    """All learned parts; ``forward(speech, poses, epoch)`` is the training loss (see the module docstring)."""

    def __init__(self, config: RhythmicConfig) -> None:
        super().__init__()
        c = self.config = config
        if c.audio_encoder not in AUDIO_ENCODERS:
            raise InputError(f"unknown audio encoder {c.audio_encoder!r}; choose one of {', '.join(AUDIO_ENCODERS)}")
        if not 1 <= c.low_layer <= c.audio_layers:
            raise InputError(f"low_layer must be in 1..{c.audio_layers}")
        self.audio = AUDIO_ENCODERS[c.audio_encoder](c)
        dims = self.audio.layer_dims
        self.low_index = min(c.low_layer, len(dims)) - 1
        self.low_dim, self.high_dim = dims[self.low_index], dims[-1]
        self.proj_t = nn.Linear(c.n_text, c.contrast_dim)  # F_t
        self.proj_a = nn.ModuleList(nn.Linear(d, c.contrast_dim) for d in dims)  # F_a^l
        self.vq = MotionVQ(c)
        self.gen = BlockGenerator(c, self.low_dim)
        n_s, d_s, d_z = c.lexicon_size, c.lexeme_dim, c.style_dim
        self.lex_interp = Interpreter(c, self.high_dim, d_s, n_s, with_text=True)
        self.lex_interp_audio = Interpreter(c, self.high_dim, d_s, n_s, with_text=False)
        self.style_interp = Interpreter(c, self.low_dim, d_z + d_s, d_z, with_text=True)
        self.style_interp_audio = Interpreter(c, self.low_dim, d_z + d_s, d_z, with_text=False)
        self.register_buffer("lex_empty", torch.zeros(n_s))  # EMA count of empty-word blocks per lexeme
        self.register_buffer("lex_total", torch.zeros(n_s))  # EMA count of all blocks per lexeme
        self.last_parts: dict[str, float] = {}

    # ---- features
    def audio_features(self, mel):
        """``mel`` ``(N, K, n_mels)`` -> ``(a_low, a_high, layers)``: ``(N, K, d_a)``, ``(N, K, d_A)``, list."""
        layers = self.audio(mel)
        return layers[self.low_index], layers[-1], layers

    def contrastive_loss(self, text, layers, mask):
        """Eq. 1: text anchors, ``a^L`` of the same frame positive, every layer of every frame of the block in the
        denominator. ``text`` ``(N, K, D)``, ``mask`` ``(N, K)`` frames inside words (where text exists)."""
        if not any(p.requires_grad for p in self.audio.parameters()) or not bool(mask.any()):
            return text.new_zeros(())
        n, k = text.shape[:2]
        t = F.normalize(self.proj_t(text), dim=-1)  # (N, K, c)
        a = torch.stack(
            [F.normalize(p(f), dim=-1) for p, f in zip(self.proj_a, layers, strict=True)], dim=1
        )  # (N, L, K, c)
        n_l = a.shape[1]
        sim = torch.einsum("nkc,nmc->nkm", t, a.reshape(n, n_l * k, -1)) / self.config.temperature  # (N, K, L * K)
        target = ((n_l - 1) * k + torch.arange(k, device=text.device)).expand(n, k)  # a_k^L is at (L - 1) * K + k
        ce = F.cross_entropy(sim.reshape(n * k, -1), target.reshape(-1), reduction="none")  # (N * K,)
        m = mask.reshape(-1).float()
        return (ce * m).sum() / m.sum()

    # ---- lexicon helpers
    def silent_mask(self):
        """Silent lexemes ``(N_s,)`` bool: mostly used on empty-word blocks (the most such one if none qualifies)."""
        share = self.lex_empty / self.lex_total.clamp_min(1e-6)
        mask = (share >= self.config.silent_share) & (self.lex_total > 1e-3)
        if not bool(mask.any()):
            mask = torch.zeros_like(mask)
            if float(self.lex_empty.max()) > 0:
                mask[self.lex_empty.argmax()] = True
        return mask

    def nearest_silent(self, s):
        """Index ``(B,)`` of the silent lexeme nearest each lexeme vector ``s`` ``(B, d_s)`` (-1: none known)."""
        mask = self.silent_mask()
        if not bool(mask.any()):
            return torch.full((s.shape[0],), -1, dtype=torch.long, device=s.device)
        d = torch.cdist(s, self.vq.codebook.detach())  # (B, N_s)
        return d.masked_fill(~mask[None], math.inf).argmin(dim=1)

    # ---- training
    def segment(self, speech, poses) -> Blocks:
        """Trainer windows ``(B, W * K, M + D + 1)``, ``(B, W * K, P)`` from :meth:`RhythmicSpec.make_windows`
        (``W`` consecutive blocks laid end to end; the last input channel flags silent blocks) -> blocks."""
        c = self.config
        k, m, d = c.block, c.n_mels, c.n_text
        b, length = speech.shape[:2]
        if speech.shape[2] != m + d + 1 or length % k:
            raise InputError(
                f"rhythmic windows are {tuple(speech.shape)}, expected (B, W * {k}, {m + d + 1}); "
                "make them with RhythmicSpec.make_windows"
            )
        w = length // k
        x = speech.reshape(b * w, k, -1)  # (B, W * K, F) -> (B * W, K, F)
        j = torch.arange(1, w - 1, device=speech.device)
        base = (torch.arange(b, device=speech.device) * w)[:, None]  # (B, 1)
        cur = (base + j[None]).reshape(-1)  # (B * (W - 2),)
        return Blocks(
            mel=x[..., :m],
            text=x[..., m : m + d] / TEXT_SCALE,
            poses=poses.reshape(b * w, k, -1),  # (B, W * K, P) -> (B * W, K, P)
            empty=x[:, 0, -1] > 0.5,
            prev=cur - 1,
            cur=cur,
            nxt=cur + 1,
        )

    def forward(self, speech, poses, epoch: int = 0):
        """Loss of trainer windows (see :meth:`segment`) at ``epoch``.

        In training mode only the stage of ``epoch`` (:meth:`RhythmicConfig.stage_at`) is computed and learns, the
        earlier ones frozen; in joint training, and in evaluation mode (the validation loss), it is the sum of all
        four stages' objectives, each gradient-isolated:

        1. audio encoder: contrastive eq. 1 (its outputs are detached downstream);
        2. lexicon: VQ-VAE eq. 3 (lexemes detached downstream; the perceptual/lexeme losses use its encoder
           through detached weights);
        3. generator + style codes: eq. 9 on teacher-forced blocks plus the inserted silent blocks (§6.4.1);
        4. interpreters: cross-entropy (lexeme; silent blocks -> nearest silent lexeme) and MSE (style code),
           with and without text, on detached inputs.
        """
        c = self.config
        stage = c.stage_at(epoch) if self.training else None
        active = STAGES if stage is None else (stage,)
        bl = self.segment(speech, poses)
        zero = speech.new_zeros(())
        parts: dict[str, Any] = {}

        if "encoder" in active:
            a_low, a_high, layers = self.audio_features(bl.mel)
            words = bl.text.max(dim=2).values > -1.0 + 1e-3  # (N, K) frames inside words
            parts["contrastive"] = self.contrastive_loss(bl.text, layers, words)
            a_low, a_high = a_low.detach(), a_high.detach()
        elif "generator" in active or "interpreters" in active:
            with torch.no_grad():
                a_low, a_high, _ = self.audio_features(bl.mel)

        if stage == "encoder":
            return self._total(parts, speech)
        if "lexicon" in active:
            parts["vq"], rec_err, idx = self.vq(bl.poses)
            parts["vq_rec"] = rec_err
        else:
            with torch.no_grad():
                idx = self.vq.quantize(self.vq.encode(bl.poses))
        if self.training:  # silent-lexeme statistics of the current lexicon
            with torch.no_grad():
                n_s = c.lexicon_size
                self.lex_total.mul_(0.98).add_(torch.bincount(idx, minlength=n_s).float())
                self.lex_empty.mul_(0.98).add_(torch.bincount(idx[bl.empty], minlength=n_s).float())
        s_all = self.vq.codebook.detach()[idx]  # (N, d_s)
        p, i, n = bl.prev, bl.cur, bl.nxt
        samples = i.numel() > 0

        if "generator" in active and samples:
            parts.update(self.generator_losses(bl, a_low, s_all, idx))
        if "interpreters" in active and samples:
            a3 = torch.cat([a_low[p], a_low[i], a_low[n]], dim=2)  # (S, K, 3 d_a)
            h3 = torch.cat([a_high[p], a_high[i], a_high[n]], dim=2)  # (S, K, 3 d_A)
            lex_t = idx[i].clone()  # targets: lexeme index, silent blocks forced to the nearest silent lexeme
            forced = self.nearest_silent(s_all[i])
            lex_t = torch.where(bl.empty[i] & (forced >= 0), forced, lex_t)
            with torch.no_grad():
                z_t = self.gen.style_code(bl.poses[i])
                z_prev = self.gen.style_code(bl.poses[p])
            ctx_z = torch.cat([z_prev, s_all[i]], dim=1)
            text_i = bl.text[i]
            l_int = zero
            for lex_net, sty_net in (
                (self.lex_interp, self.style_interp),
                (self.lex_interp_audio, self.style_interp_audio),
            ):
                l_int = l_int + F.cross_entropy(lex_net(h3, text_i, s_all[p]), lex_t)
                l_int = l_int + F.mse_loss(sty_net(a3, text_i, ctx_z), z_t)
            parts["interp"] = l_int
        return self._total(parts, speech)

    def _total(self, parts: dict[str, Any], speech):
        """Sum of the stages' objectives in ``parts`` (the other entries are their terms, logged only)."""
        self.last_parts = {k: float(v.detach()) for k, v in parts.items()}
        total = sum((parts[k] for k in STAGE_LOSSES if k in parts), speech.new_zeros(()))
        if self.training and not total.requires_grad:  # nothing to learn in this batch (e.g. no words to contrast)
            total = total + speech.new_zeros((), requires_grad=True)
        return total

    def generator_losses(self, bl: Blocks, a_low, s_all, idx) -> dict[str, Any]:
        """Eq. 9 (``"gen"``, with its parts for the log) on teacher-forced blocks plus inserted silent blocks:
        after empty-word blocks, noise audio, z = 0, the nearest silent lexeme, the previous block's last pose held
        still (§6.4.1). The paper inserts runs of 0-10 silent blocks; a block inside a run follows another silent
        block, so :data:`SILENT_RUN_LATER` of the inserted blocks get the held pose as their previous block too."""
        c = self.config
        p, i, n = bl.prev, bl.cur, bl.nxt
        a3 = torch.cat([a_low[p], a_low[i], a_low[n]], dim=2)  # (S, K, 3 d_a)
        prev_m, target = bl.poses[p], bl.poses[i]
        z = self.gen.style_code(target)  # (S, d_z)
        s = s_all[i]
        after_empty = torch.nonzero(bl.empty[p]).flatten()
        silent_of_prev = self.nearest_silent(s_all[p])
        n_aug = round(c.silent_augment / max(1.0 - c.silent_augment, 1e-6) * i.numel())
        if self.training and after_empty.numel() and n_aug and bool((silent_of_prev >= 0).all()):
            pick = after_empty[torch.randint(0, after_empty.numel(), (max(1, n_aug),), device=a_low.device)]
            pp = p[pick]
            still = bl.poses[pp][:, -1:].expand(-1, c.block, -1)  # (A, K, P) the empty block's last pose held
            later = torch.rand(pick.numel(), device=a_low.device) < SILENT_RUN_LATER  # follows an inserted block
            prev_m = torch.cat([prev_m, torch.where(later[:, None, None], still, bl.poses[pp])])
            a3 = torch.cat([a3, a_low[pp].repeat(1, 1, 3)])
            s = torch.cat([s, self.vq.codebook.detach()[silent_of_prev[pick]]])
            z = torch.cat([z, z.new_zeros(pick.numel(), c.style_dim)])
            target = torch.cat([target, still])
        n_real = i.numel()

        gen = self.gen(prev_m, a3, s, z)  # (S', K, P)
        l_rec = F.mse_loss(gen, target)
        l_perc = F.mse_loss(self.vq.encode(gen, frozen=True), self.vq.encode(target, frozen=True).detach())
        perm = torch.randperm(n_real, device=a_low.device)  # eq. 12: same lexeme, another block's other inputs
        other = self.gen(prev_m[:n_real][perm], a3[:n_real][perm], s[:n_real], z[:n_real][perm])
        l_lex = F.mse_loss(self.vq.encode(other, frozen=True), s[:n_real])
        zr = z[:n_real]
        mu, var = zr.mean(0), zr.var(0, unbiased=False) + 1e-6
        l_z = 0.5 * (mu**2 + var - var.log() - 1.0).mean()  # eq. 14 on the batch statistics
        l_gen = c.w_rec * l_rec + c.w_perc * l_perc + c.w_lexeme * l_lex + c.w_z * l_z
        return {"gen": l_gen, "rec": l_rec, "perc": l_perc, "lexeme": l_lex, "kl": l_z}


class RhythmicSpec:
    """The trainer's view of the model (:class:`robogest.learn.trainer.ModelSpec`)."""

    name = "rhythmic"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> RhythmicConfig:
        front = FeatureConfig().speech_config()  # the trainer's feature front-end: its rate and mel analysis
        fixed = {"n_acoustic": n_acoustic, "n_text": n_text, "n_pose": n_pose, "n_mels": front.n_mels,
                 "audio_sr": front.sr, "mel_window_s": front.mel_window_s, "fps": front.fps}  # fmt: skip
        return config_with_overrides(RhythmicConfig, "rhythmic", overrides, **fixed)

    def config_from_dict(self, d: dict[str, Any]) -> RhythmicConfig:
        return RhythmicConfig.from_dict(d)

    def plan_epochs(self, config: RhythmicConfig, epochs: int) -> RhythmicConfig:
        """Give each stage its share of ``epochs`` (at least one each) when training sequentially.

        Raises
        ------
        InputError
            Fewer epochs than stages.
        """
        if config.stages == "joint":
            return config
        trainable = AUDIO_ENCODERS[config.audio_encoder].trainable
        present = [
            w > 0 and (name != "encoder" or trainable) for name, w in zip(STAGES, config.stage_weights, strict=True)
        ]
        names = [name for name, p in zip(STAGES, present, strict=True) if p]
        if epochs < len(names):
            raise InputError(
                f"the rhythmic model trains its stages ({', '.join(names)}) one after another and needs --epochs >= "
                f"{len(names)} (got {epochs}); or train them together with --set stages=joint"
            )
        weights = np.array([w if p else 0.0 for w, p in zip(config.stage_weights, present, strict=True)])
        share = (epochs - len(names)) * weights / weights.sum()  # the epochs beyond one per stage, by weight
        alloc = np.floor(share).astype(int) + np.asarray(present, int)
        for j in np.argsort(-(share - np.floor(share)))[: epochs - int(alloc.sum())]:  # largest remainders
            alloc[j] += 1
        return dataclasses.replace(config, stage_ends=tuple(int(e) for e in np.cumsum(alloc)))

    def first_best_epoch(self, config: RhythmicConfig) -> int:
        """``best.pt`` is chosen among the epochs of the last stage, when every part has been trained."""
        return config.stage_ends[-2] if config.stage_at(0) is not None else 0

    def stage_name(self, epoch: int, config: RhythmicConfig) -> str:
        return config.stage_at(epoch) or "all stages"

    def build(self, config: RhythmicConfig) -> RhythmicNet:
        return RhythmicNet(config)

    def sequence_length(self, config: RhythmicConfig) -> int:
        return config.window_blocks * config.block

    def make_windows(self, takes, norm, config: RhythmicConfig, length: int, stride: int):
        """Windows of ``length // K`` consecutive beat blocks of each whole take (:func:`take_blocks`).

        Beats and silent blocks are found once on the whole take, as at run time on the whole speech. The audio
        blocks come from each take's recording, time-scaled and re-analysed (a take without ``audio_path``: from
        its log-mel frames). Consecutive windows start about ``stride`` frames apart (``stride`` over the take's
        mean clip length, in blocks).

        Returns
        -------
        x : ndarray [shape=(N, W * K, n_mels + D + 1)], float32
            Standardised time-scaled log-mel, raw text, silent-block flag; block ``w`` is frames ``[w K, (w + 1) K)``.
        y : ndarray [shape=(N, W * K, P)], float32
            Normalised poses.
        take_index : ndarray [shape=(N,)], int
        """
        k, m = config.block, config.n_mels
        w = length // k
        xs, ys, idx = [], [], []
        for i, t in enumerate(takes):
            audio = t.read_audio(config.audio_sr) if config.audio_tsm and t.audio_path is not None else None
            tb = take_blocks(t.acoustic[:, :m], t.text, norm, config, audio, t.poses)
            n_c = tb.silent.shape[0]
            if n_c < w:
                continue
            flag = np.broadcast_to(tb.silent[:, None, None], (n_c, k, 1))
            x = np.concatenate([tb.mel, tb.text, flag], axis=2).reshape(n_c, -1)  # (C, K, F) -> (C, K * F)
            y = tb.poses.reshape(n_c, -1)  # (C, K, P) -> (C, K * P)
            step = max(1, round(stride * n_c / t.n_frames))  # frames -> blocks
            xw, yw, _ = slice_windows([(i, x, y)], w, step, x.shape[1], y.shape[1])  # (N_i, W, K * F)
            xs.append(xw.reshape(xw.shape[0], w * k, -1))  # (N_i, W, K * F) -> (N_i, W * K, F)
            ys.append(yw.reshape(yw.shape[0], w * k, -1))
            idx.append(np.full(xw.shape[0], i))
        if not xs:
            f = m + config.n_text + 1
            return (
                np.zeros((0, w * k, f), np.float32),
                np.zeros((0, w * k, config.n_pose), np.float32),
                np.zeros(0, int),
            )
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(idx)

    def loss(self, model, speech, poses, epoch: int, config: RhythmicConfig):
        return model(speech, poses, epoch)  # through the (possibly DDP) wrapper's forward


SPEC = RhythmicSpec()


# --------------------------------------------------------------------------------------------------- inference
@dataclass
class BlockPlan:
    """What :meth:`RhythmicGenerator.generate_blocks` decided, for evaluation (e.g. lexeme entropy, eq. 23).

    ``bounds`` ``(C + 1,)`` clip boundaries (frames); ``lexemes`` ``(C,)``; ``silent`` ``(C,)`` bool;
    ``poses`` ``(T, P)`` denormalised, smoothed exponential maps (radians).
    """

    bounds: np.ndarray
    lexemes: np.ndarray
    silent: np.ndarray
    poses: np.ndarray


class RhythmicGenerator(CheckpointGenerator):
    """Generator backed by a checkpoint from ``robogest train --model rhythmic``.

    Parameters
    ----------
    checkpoint : path-like
        ``.pt`` file (model, feature and normalisation settings).
    device : str
        Torch device (CPU is fast enough: one block of 0.2-0.5 s costs a few small network calls).
    encoder : TextEncoder, optional
        Overrides the checkpoint's text encoder (same dimension).
    """

    name = "rhythmic"
    config_cls = RhythmicConfig
    net_cls = RhythmicNet

    def generate_blocks(
        self,
        speech: Speech,
        lexemes: np.ndarray | None = None,
        styles: np.ndarray | None = None,
        force_silent: bool = True,
        temperature: float = 0.0,
        generator=None,
    ) -> BlockPlan:
        """Blocks at the beats of :func:`take_rhythm`, lexemes/styles from the interpreters (or given), motion
        denormalised.

        Parameters
        ----------
        speech : Speech
            At the model's frame rate.
        lexemes : ndarray [shape=(C,)], int, optional
            Force these lexemes (e.g. the ground truth's, to test the generator alone); silent blocks are still
            forced to a silent lexeme only when ``lexemes`` is None.
        styles : ndarray [shape=(C, d_z)], optional
            Force these style codes.
        force_silent : bool
            Apply the silent-period hint at run time (silent blocks get the silent lexeme nearest the previous one
            and style code 0); False shows what the interpreters alone choose.
        temperature : float
            0: the interpreter's most likely lexeme; > 0: a sample of its softmax at this temperature.
        generator : torch.Generator, optional
            Random source of the samples (``temperature > 0``).
        """
        c, m = self.config, self.model
        k, t_frames = c.block, speech.n_frames
        acoustic, text = speech_inputs(speech, self.features, self.encoder)  # (T, 69), (T, D)
        with_text = len(speech.words) > 0
        audio = None
        if c.audio_tsm:
            from robogest.speech.audio import resample

            audio = resample(speech.audio, speech.sr, c.audio_sr)
        tb = take_blocks(acoustic[:, : c.n_mels], text, self.norm, c, audio)
        bounds, silent = tb.bounds, tb.silent  # (C + 1,), (C,)
        n_b = len(bounds) - 1
        if n_b == 0 or t_frames == 0:
            return BlockPlan(bounds, np.zeros(0, int), np.zeros(0, bool), np.zeros((0, c.n_pose), np.float32))
        blk = np.concatenate([tb.mel, tb.text / TEXT_SCALE], axis=2)  # (C, K, M + D)
        dev = self.device
        with torch.inference_mode():
            b = torch.from_numpy(blk.astype(np.float32)).to(dev)
            mel, txt = b[..., : c.n_mels], b[..., c.n_mels :]
            a_low, a_high, _ = m.audio_features(mel)  # (C, K, d_a), (C, K, d_A)
            ip = np.maximum(np.arange(n_b) - 1, 0)
            inx = np.minimum(np.arange(n_b) + 1, n_b - 1)
            a3 = torch.cat([a_low[ip], a_low, a_low[inx]], dim=2)  # (C, K, 3 d_a)
            h3 = torch.cat([a_high[ip], a_high, a_high[inx]], dim=2)  # (C, K, 3 d_A)
            lex_net = m.lex_interp if with_text else m.lex_interp_audio
            sty_net = m.style_interp if with_text else m.style_interp_audio
            codebook = m.vq.codebook
            prev = torch.zeros(1, k, c.n_pose, device=dev)  # the mean pose (normalised zeros)
            s_prev = codebook[m.vq.quantize(m.vq.encode(prev))]  # (1, d_s)
            z_prev = torch.zeros(1, c.style_dim, device=dev)
            out, lex_ids = [], np.zeros(n_b, int)
            for j in range(n_b):
                if lexemes is not None:
                    lex = int(lexemes[j])
                else:
                    logits = lex_net(h3[j : j + 1], txt[j : j + 1], s_prev)  # (1, N_s)
                    if temperature > 0:
                        p = torch.softmax(logits / temperature, dim=1)
                        lex = int(torch.multinomial(p.cpu(), 1, generator=generator))
                    else:
                        lex = int(logits.argmax(dim=1))
                    if silent[j] and force_silent:
                        forced = int(m.nearest_silent(s_prev)[0])
                        lex = forced if forced >= 0 else lex
                s = codebook[lex][None]  # (1, d_s)
                if styles is not None:
                    z = torch.as_tensor(styles[j : j + 1], dtype=torch.float32, device=dev)
                elif silent[j] and lexemes is None and force_silent:
                    z = torch.zeros(1, c.style_dim, device=dev)  # silent blocks: z = 0 (§6.4.1)
                else:
                    z = sty_net(a3[j : j + 1], txt[j : j + 1], torch.cat([z_prev, s], dim=1))
                y = m.gen(prev, a3[j : j + 1], s, z)  # (1, K, P)
                out.append(y[0])
                lex_ids[j] = lex
                prev, s_prev, z_prev = y, s, z
            blocks = torch.stack(out).cpu().numpy()  # (C, K, P)
        poses = denormalize_blocks(blocks, np.diff(bounds))  # (T, P), normalised
        poses = self.norm.pose_inverse(gaussian_smooth(poses, c.smooth_kernel))
        return BlockPlan(bounds, lex_ids, silent, poses)

    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion at ``speech.fps`` with exactly ``speech.n_frames`` frames.

        Each lexeme is sampled from the interpreter's softmax at ``config.lexeme_temperature`` with a torch
        generator seeded by ``seed`` (the same seed gives the same motion, another seed other lexemes); silent
        blocks still get the silent lexeme. The Gumbel latent takes its most likely categories.
        """
        s = self.at_model_rate(speech)
        g = torch.Generator().manual_seed(int(seed))
        plan = self.generate_blocks(s, temperature=self.config.lexeme_temperature, generator=g)
        return expmap_to_motion(plan.poses, s.fps).resample(speech.fps, n_frames=speech.n_frames)
