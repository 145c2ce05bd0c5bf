"""The Rhythmic Gesticulator's parts: audio encoders (§4.1.3), gesture lexicon VQ-VAE (§5.1), block generator
(§5.2-5.3) and interpreters (§6.1-6.3)."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

from robogest.learn import require_torch

if TYPE_CHECKING:  # the checker sees torch's own types; at run time a missing torch is one clear error
    import torch
    from torch import Tensor, nn
    from torch.nn import functional as F

    #: The decoder LSTM's ``(h, c)``.
    LSTMState = tuple[Tensor, Tensor]
else:
    torch = require_torch("the 'rhythmic' generator")
    nn = torch.nn
    F = torch.nn.functional

from robogest.generators.learned.rhythmic.config import RhythmicConfig
from robogest.learn.dist import Sync


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

    def forward(self, mel: Tensor) -> list[Tensor]:
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

    def forward(self, mel: Tensor) -> list[Tensor]:
        return [mel]


#: Audio encoders by name: ``cls(config)`` with ``layer_dims``, ``trainable`` (has a pre-training stage) and
#: ``forward(mel) -> [per-layer (B, K, C_l)]``.
AUDIO_ENCODERS: dict[str, type[ConvAudioEncoder | MelAudioEncoder]] = {"conv": ConvAudioEncoder, "mel": MelAudioEncoder}


# --------------------------------------------------------------------------------------------------- lexicon
class MotionVQ(nn.Module):
    """VQ-VAE of §5.1: 4 conv layers + FC -> lexeme space (d_s), codebook of ``lexicon_size``, mirrored decoder."""

    usage: Tensor  # buffer (N_s,)
    initialised: Tensor  # buffer (), bool

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

    def encode(self, m: Tensor, frozen: bool = False) -> Tensor:
        """Motion blocks ``(B, K, P)`` -> ``E(M)`` ``(B, d_s)``; ``frozen``: through detached weights (no update)."""
        x = m.transpose(1, 2)  # (B, P, K)
        if not frozen:
            out: Tensor = self.enc(x)
            return out
        params = {n: p.detach() for n, p in self.enc.named_parameters()}
        frozen_out: Tensor = torch.func.functional_call(self.enc, params, (x,))
        return frozen_out

    def decode(self, s: Tensor) -> Tensor:
        """``(B, d_s)`` -> ``(B, K, P)``."""
        h = self.dec_fc(s).view(s.shape[0], self.ch, self.k)  # (B, ch * K) -> (B, ch, K)
        out: Tensor = self.dec(h)  # (B, P, K)
        return out.transpose(1, 2)  # (B, P, K) -> (B, K, P)

    def quantize(self, e: Tensor) -> Tensor:
        """Nearest codebook entries (eq. 4): indices ``(B,)``."""
        return torch.cdist(e, self.codebook.detach()).argmin(dim=1)

    def forward(self, m: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Eq. 3 loss, reconstruction error and indices of motion blocks ``(B, K, P)``.

        Changes no state: the codebook's upkeep is :meth:`maintain`, called by the trainer before the step."""
        e = self.encode(m)  # (B, d_s)
        idx = self.quantize(e)
        s = self.codebook[idx]  # (B, d_s)
        rec = self.decode(e + (s - e).detach())  # straight-through gradient to the encoder
        rec_err = F.mse_loss(rec, m)
        loss = rec_err + self.cfg_alpha * F.mse_loss(e, s.detach()) + self.cfg_beta * F.mse_loss(e.detach(), s)
        return loss, rec_err.detach(), idx

    @torch.no_grad()
    def maintain(self, e: Tensor, sync: Sync | None = None) -> None:
        """Data-dependent start and dead-code restart, so the small lexicon is actually used (not in eq. 3).

        ``e`` ``(B, d_s)``: this batch's (this rank's shard's) encodings. Under DDP (``sync``) every rank makes the
        same change: the usage EMA comes from code counts summed over ranks, and the vectors that (re)start codes
        are rank 0's, broadcast. The same collectives run on every rank whatever its batch holds.
        """
        n = self.codebook.shape[0]
        if not bool(self.initialised):
            if sync is None or sync.is_main:
                pick = torch.randint(0, e.shape[0], (n,), device=e.device)
                self.codebook.data.copy_(e[pick] + 0.01 * torch.randn_like(e[pick]))
            if sync is not None:
                sync.broadcast_(self.codebook.data)
            self.initialised.fill_(True)
        idx = self.quantize(e)
        counts = torch.cat([torch.bincount(idx, minlength=n).float(), idx.new_full((1,), idx.numel()).float()])
        if sync is not None:
            sync.all_reduce_sum_(counts)  # (n + 1,): per-code counts and the number of encodings, all ranks
        hist = counts[:n] / max(int(counts[n]), 1)
        self.usage.mul_(0.95).add_(0.05 * hist * n)
        dead = self.usage < 0.02  # the same on every rank: from the summed counts
        if dead.any():
            if sync is None or sync.is_main:
                pick = torch.randint(0, e.shape[0], (int(dead.sum()),), device=e.device)
                self.codebook.data[dead] = e[pick] + 0.01 * torch.randn_like(e[pick])
            if sync is not None:
                sync.broadcast_(self.codebook.data)
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

    pe: Tensor  # buffer (K, d_P), eq. 8

    def __init__(self, c: RhythmicConfig, low_dim: int) -> None:
        super().__init__()
        self.c = c
        self.e_m = _conv_stack(c.n_pose, c.hidden, c.motion_feat_dim, 3)  # E_M, 3 conv layers (eq. 6)
        self.e_a = nn.Linear(3 * low_dim, c.audio_feat_dim)  # E_A, one FC layer (eq. 7)
        self.register_buffer("pe", torch.from_numpy(positional_encoding(c.block, c.pe_dim)))
        n_in = c.motion_feat_dim + c.audio_feat_dim + c.lexeme_dim + c.style_dim + c.pe_dim  # eq. 5: no speaker
        self.mlp = nn.Sequential(
            nn.Linear(n_in, c.hidden), nn.LeakyReLU(0.2), nn.Linear(c.hidden, c.latent_groups * c.latent_classes)
        )
        self.latent = nn.Parameter(torch.randn(c.latent_groups, c.latent_classes, c.latent_group_dim) * 0.5)
        self.lstm = nn.LSTM(c.latent_groups * c.latent_group_dim + c.motion_feat_dim, c.hidden, batch_first=True)
        self.out = nn.Linear(c.hidden, c.n_pose)

    def forward(
        self, prev: Tensor, a_low3: Tensor, s: Tensor, z: Tensor, state: LSTMState | None = None
    ) -> tuple[Tensor, LSTMState]:
        """One block, continuing the LSTM ``state`` of the previous block (None: a fresh start).

        Parameters
        ----------
        prev : Tensor [shape=(B, K, P)]
            Previous (normalised) motion block.
        a_low3 : Tensor [shape=(B, K, 3 * d_a)]
            ``a_low`` of blocks i-1, i, i+1 side by side.
        s : Tensor [shape=(B, d_s)]
            Lexeme vector.
        z : Tensor [shape=(B, d_z)]
        state : tuple of Tensor, optional
            The decoder LSTM's ``(h, c)`` after the previous block; the authors' generator runs block after block
            with its state carried over.

        Returns
        -------
        motion : Tensor [shape=(B, K, P)]
        state : tuple of Tensor
            ``(h, c)`` after this block, for the next.
        """
        c = self.c
        b, k = prev.shape[0], c.block
        m_feat = self.e_m(prev.transpose(1, 2)).transpose(1, 2)  # (B, P, K) -> (B, d_m, K) -> (B, K, d_m)
        parts = [m_feat, self.e_a(a_low3), s[:, None].expand(b, k, -1), z[:, None].expand(b, k, -1),
                 self.pe[None].expand(b, k, -1)]  # fmt: skip
        cond = torch.cat(parts, dim=2)  # (B, K, n_in)
        logits = self.mlp(cond).view(b, k, c.latent_groups, c.latent_classes)  # (B, K, H * C) -> (B, K, H, C)
        if self.training:
            w = F.gumbel_softmax(logits, tau=c.gumbel_tau, hard=True, dim=-1)  # one-hot forward, as at run time
            q = torch.einsum("bkhc,hcd->bkhd", w, self.latent)  # (B, K, H, d_g)
        else:  # the most likely category's vector: a gather, not a product with a one-hot
            groups = torch.arange(c.latent_groups, device=logits.device)
            q = self.latent[groups, logits.argmax(-1)]  # (H,), (B, K, H) -> (B, K, H, d_g)
        q = q.reshape(b, k, -1)  # (B, K, H, d_g) -> (B, K, H * d_g)
        h, state = self.lstm(torch.cat([q, m_feat], dim=2), state)  # (B, K, hidden)
        return self.out(h), state  # (B, K, P)


# --------------------------------------------------------------------------------------------------- interpreters
class Interpreter(nn.Module):
    """LSTM over a block's condition frames -> last state -> head (lexeme logits or style code, §6.1-6.2).

    ``with_text=False`` is the audio-only variant (§6.3): the text branch is absent. ``with_speaker``: the speaker
    ID ``I`` joins the inputs as a feature block (eq. 16, the lexeme interpreters; eq. 19's style interpreter has
    none), through an embedding of ``config.speaker_dim`` (a linear layer of the one-hot ``I``).
    """

    def __init__(
        self, c: RhythmicConfig, audio_dim: int, ctx_dim: int, n_out: int, with_text: bool, with_speaker: bool = False
    ) -> None:
        super().__init__()
        self.with_text = with_text
        self.e_a = nn.Linear(3 * audio_dim, c.audio_feat_dim)  # E_A^lex / E_A^style: one FC layer
        self.e_t = nn.Linear(c.n_text, c.audio_feat_dim) if with_text else None  # E_T: one FC layer
        use_speaker = with_speaker and c.speaker_dim > 0
        self.speaker = nn.Embedding(max(1, len(c.speakers)), c.speaker_dim) if use_speaker else None
        n_in = c.audio_feat_dim * (2 if with_text else 1) + ctx_dim + (c.speaker_dim if use_speaker else 0)
        self.lstm = nn.LSTM(n_in, c.hidden, batch_first=True)
        self.head = nn.Linear(c.hidden, n_out)

    def forward(self, audio3: Tensor, text: Tensor, ctx: Tensor, speaker: Tensor | None = None) -> Tensor:
        """``audio3`` ``(B, K, 3 * d)``, ``text`` ``(B, K, D)`` (ignored audio-only), ``ctx`` ``(B, d_ctx)``,
        ``speaker`` ``(B,)`` long indices into ``config.speakers`` (default 0; unused without a speaker input)."""
        b, k = audio3.shape[:2]
        parts = [self.e_a(audio3)]
        if self.e_t is not None:
            parts.append(self.e_t(text))
        parts.append(ctx[:, None].expand(b, k, -1))
        if self.speaker is not None:
            spk = speaker if speaker is not None else torch.zeros(b, dtype=torch.long, device=audio3.device)
            parts.append(self.speaker(spk)[:, None].expand(b, k, -1))  # (B, K, speaker_dim)
        h, _ = self.lstm(torch.cat(parts, dim=2))  # (B, K, hidden)
        out: Tensor = self.head(h[:, -1])  # (B, n_out)
        return out
