"""Rhythmic Gesticulator (Ao et al., SIGGRAPH Asia 2022, §4-6): beat-normalised blocks, gesture lexicon, interpreters.

Importing this module needs PyTorch; register the generator through a lazy factory.

Data (§4.2, :mod:`.blocks`, :func:`take_blocks`): speech and motion are cut at beats and every clip is
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
  Gumbel-softmax latent -> LSTM decoder (no speaker input: eq. 5). Style codes: one learnable vector per training
  block (:attr:`RhythmicNet.style_codes`), trained with the generator. Losses: reconstruction, perceptual (0.5),
  lexeme (0.2), style KL (1.0).
* interpreters (§6.1-6.3): lexeme classifier from ``a_high``, text, the previous lexeme and the speaker (eq. 16);
  style regressor from ``a_low``, text, the previous style code and the lexeme (eq. 19), trained on the learned
  codes; each with an audio-only twin. At run time they choose every block's lexeme and style code.
* silent-period hint (§6.4.1): lexemes mostly seen on silent blocks are the silent lexemes; silent blocks get
  the silent lexeme nearest the current (training) or previous (inference) one; ~5 % silent blocks are added to
  the generator's training batch. A silent block has no words and, in takes without any words, mostly quiet frames
  (:func:`.blocks.silent_blocks`), so takes without transcripts train the hint too.

Beats (§4.2.1): training takes and run-time speech are cut by the speech front-end's rule on the waveform
(``Speech.beats_s``; :func:`.take.take_beats` for a cached training take's recording), and turned into blocks by one
function, :func:`.take.take_blocks`. Only frames without their recording fall back to beats of the log-mel frames
(:func:`.blocks.frame_beats`).

Training through :func:`robogest.learn.trainer.train`: :meth:`RhythmicSpec.make_windows` cuts every take into
blocks once and hands the trainer windows of ``window_blocks`` consecutive blocks. The paper's stages run one after
another (``stages="sequential"``, the default): audio-encoder pre-training, lexicon, generator, interpreters, each
for its share of ``--epochs`` (:meth:`RhythmicSpec.plan_epochs`), every earlier stage frozen. ``stages="joint"``
trains all four at once, each only by its own objective (downstream parts read detached outputs of upstream ones).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from robogest.learn import require_torch

if TYPE_CHECKING:  # the checker sees torch's own types; at run time a missing torch is one clear error
    import torch
    from torch import Tensor, nn
    from torch.nn import functional as F

    from robogest.learn.dist import Sync
else:
    torch = require_torch("the 'rhythmic' generator")
    nn = torch.nn
    F = torch.nn.functional

from robogest.errors import InputError
from robogest.generators.learned.rhythmic.config import (
    SILENT_RUN_LATER,
    STAGE_LOSSES,
    STAGES,
    TEXT_SCALE,
    RhythmicConfig,
)
from robogest.generators.learned.rhythmic.networks import AUDIO_ENCODERS, BlockGenerator, Interpreter, MotionVQ


# --------------------------------------------------------------------------------------------------- whole model
@dataclass
class Blocks:
    """The blocks of a batch of training windows (tensors) and the training samples among them.

    ``mel`` ``(N, K, n_mels)``, ``text`` ``(N, K, D)`` (scaled: silence = -1), ``poses`` ``(N, K, P)``, ``empty``
    ``(N,)`` bool (silent block: :func:`.blocks.silent_blocks`); ``speaker`` ``(N,)`` long (``config.speakers``);
    ``style_row`` ``(N,)`` long (the block's row of :attr:`RhythmicNet.style_codes`, -1: not a training block);
    ``prev``, ``cur``, ``nxt`` ``(S,)``
    block indices of the samples (every block but a window's first and last, which serve as context), window by
    window: sample ``w * (W - 2) + j`` is block ``j + 1`` of window ``w``.
    """

    mel: Any
    text: Any
    poses: Any
    empty: Any
    prev: Any
    cur: Any
    nxt: Any
    per_window: int
    speaker: Any
    style_row: Any


class RhythmicNet(nn.Module):
    """All learned parts; ``forward(speech, poses, epoch)`` is the training loss (see the module docstring)."""

    lex_empty: Tensor  # buffer (N_s,)
    lex_total: Tensor  # buffer (N_s,)

    def __init__(self, config: RhythmicConfig) -> None:
        super().__init__()
        c = self.config = config
        if c.audio_encoder not in AUDIO_ENCODERS:
            raise InputError(f"unknown audio encoder {c.audio_encoder!r}; choose one of {', '.join(AUDIO_ENCODERS)}")
        if not 1 <= c.low_layer <= c.audio_layers:
            raise InputError(f"low_layer must be in 1..{c.audio_layers}")
        self.audio = AUDIO_ENCODERS[c.audio_encoder](c)
        self.low_index = min(c.low_layer, len(self.audio.layer_dims)) - 1
        dims = [*self.audio.layer_dims, *([c.speech_dim] if c.speech_encoder else [])]  # pretrained: a_high
        self.low_dim, self.high_dim = dims[self.low_index], dims[-1]
        self.proj_t = nn.Linear(c.n_text, c.contrast_dim)  # F_t
        self.proj_a = nn.ModuleList(nn.Linear(d, c.contrast_dim) for d in dims)  # F_a^l
        self.vq = MotionVQ(c)
        self.gen = BlockGenerator(c, self.low_dim)
        n_s, d_s, d_z = c.lexicon_size, c.lexeme_dim, c.style_dim
        # {z_i} of §5.3: one free style code per training block, learned with the generator (N(0, 1) start: eq. 14)
        self.style_codes = nn.Embedding(c.n_style_rows, d_z)
        self.lex_interp = Interpreter(c, self.high_dim, d_s, n_s, with_text=True, with_speaker=True)  # eq. 16
        self.lex_interp_audio = Interpreter(c, self.high_dim, d_s, n_s, with_text=False, with_speaker=True)
        self.style_interp = Interpreter(c, self.low_dim, d_z + d_s, d_z, with_text=True)
        self.style_interp_audio = Interpreter(c, self.low_dim, d_z + d_s, d_z, with_text=False)
        self.register_buffer("lex_empty", torch.zeros(n_s))  # EMA count of empty-word blocks per lexeme
        self.register_buffer("lex_total", torch.zeros(n_s))  # EMA count of all blocks per lexeme
        self.last_parts: dict[str, float] = {}

    # ---- features
    def audio_features(self, mel: Tensor) -> tuple[Tensor, Tensor, list[Tensor]]:
        """``mel`` ``(N, K, n_audio)`` -> ``(a_low, a_high, layers)``: ``(N, K, d_a)``, ``(N, K, d_A)``, list."""
        layers = self.audio(mel[..., : self.config.n_mels])
        if self.config.speech_encoder:  # the pretrained speech encoder's features are the last, high-level layer
            layers = [*layers, mel[..., self.config.n_mels :]]
        return layers[self.low_index], layers[-1], layers

    def contrastive_loss(self, text: Tensor, layers: list[Tensor], mask: Tensor) -> Tensor:
        """Eq. 1: text anchors, ``a^L`` of the same frame positive, every layer of every frame of the block in the
        denominator. ``text`` ``(N, K, D)``, ``mask`` ``(N, K)`` frames inside words (where text exists)."""
        if not any(p.requires_grad for p in self.audio.parameters()):
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
        # A batch without words gives 0 through every encoder weight: under DDP its backward still joins the
        # gradient all-reduce, which a loss without a graph skipped (the other ranks then waited for ever).
        return (ce * m).sum() / m.sum().clamp_min(1.0)

    # ---- lexicon helpers
    def silent_mask(self) -> Tensor:
        """Silent lexemes ``(N_s,)`` bool: mostly used on empty-word blocks (the most such one if none qualifies)."""
        share = self.lex_empty / self.lex_total.clamp_min(1e-6)
        mask = (share >= self.config.silent_share) & (self.lex_total > 1e-3)
        if not bool(mask.any()):
            mask = torch.zeros_like(mask)
            if float(self.lex_empty.max()) > 0:
                mask[self.lex_empty.argmax()] = True
        return mask

    def nearest_silent(self, s: Tensor) -> Tensor:
        """Index ``(B,)`` of the silent lexeme nearest each lexeme vector ``s`` ``(B, d_s)`` (-1: none known)."""
        mask = self.silent_mask()
        if not bool(mask.any()):
            return torch.full((s.shape[0],), -1, dtype=torch.long, device=s.device)
        d = torch.cdist(s, self.vq.codebook.detach())  # (B, N_s)
        return d.masked_fill(~mask[None], math.inf).argmin(dim=1)

    def block_styles(self, rows: Tensor) -> Tensor:
        """Learned style codes ``(N, d_z)`` of blocks with style-code ``rows`` ``(N,)``; 0 where a row is -1 (not a
        training block: a validation take's, whose codes at run time come from the style interpreter)."""
        codes: Tensor = self.style_codes(rows.clamp_min(0))  # (N, d_z)
        return codes * (rows >= 0)[:, None]

    # ---- training
    def segment(self, speech: Tensor, poses: Tensor) -> Blocks:
        """Trainer windows ``(B, W * K, M + D + 3)``, ``(B, W * K, P)`` from :meth:`RhythmicSpec.make_windows`
        (``W`` consecutive blocks laid end to end; the last three input channels: silent-block flag, speaker index,
        style-code row) -> blocks."""
        c = self.config
        k, m, d = c.block, c.n_audio, c.n_text
        b, length = speech.shape[:2]
        if speech.shape[2] != m + d + 3 or length % k:
            raise InputError(
                f"rhythmic windows are {tuple(speech.shape)}, expected (B, W * {k}, {m + d + 3}); "
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
            empty=x[:, 0, -3] > 0.5,
            speaker=x[:, 0, -2].round().long(),
            style_row=x[:, 0, -1].round().long(),
            prev=cur - 1,
            cur=cur,
            nxt=cur + 1,
            per_window=w - 2,
        )

    @torch.no_grad()
    def before_step(self, speech: Tensor, poses: Tensor, epoch: int = 0, sync: Sync | None = None) -> None:
        """The state that is not learned by gradient, updated from a training batch before its step: the lexicon's
        codebook upkeep (:meth:`MotionVQ.maintain`, while the lexicon trains) and the silent-lexeme statistics.

        Kept out of :meth:`forward` so that under DDP (``sync``: :class:`robogest.learn.dist.Sync`) every rank
        makes the same change from statistics summed over ranks, and ranks keep identical weights and buffers.
        """
        c = self.config
        stage = c.stage_at(epoch)
        if stage == "encoder":
            return  # the forward pass reads no lexeme
        bl = self.segment(speech, poses)
        e = self.vq.encode(bl.poses)  # (N, d_s)
        if stage is None or stage == "lexicon":
            self.vq.maintain(e, sync)
        idx = self.vq.quantize(e)
        n_s = c.lexicon_size
        counts = torch.cat([torch.bincount(idx, minlength=n_s), torch.bincount(idx[bl.empty], minlength=n_s)])
        counts = counts.float()  # (2 N_s,): all blocks, empty-word blocks
        if sync is not None:
            sync.all_reduce_sum_(counts)
        self.lex_total.mul_(0.98).add_(counts[:n_s])
        self.lex_empty.mul_(0.98).add_(counts[n_s:])

    def forward(self, speech: Tensor, poses: Tensor, epoch: int = 0) -> Tensor:
        """Loss of trainer windows (see :meth:`segment`) at ``epoch``.

        In training mode only the stage of ``epoch`` (:meth:`RhythmicConfig.stage_at`) is computed and learns, the
        earlier ones frozen; in joint training, and in evaluation mode, it is the sum of all four stages' objectives,
        each gradient-isolated (``best.pt`` is chosen on free-running generation instead:
        :meth:`RhythmicSpec.validation_loss`):

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
            with torch.no_grad():  # targets: the learned style codes of the blocks (§6.4)
                z_t = self.block_styles(bl.style_row[i])
                z_prev = self.block_styles(bl.style_row[p])
            ctx_z = torch.cat([z_prev, s_all[i]], dim=1)
            text_i, spk = bl.text[i], bl.speaker[i]
            l_int = zero
            for lex_net, sty_net in (
                (self.lex_interp, self.style_interp),
                (self.lex_interp_audio, self.style_interp_audio),
            ):
                l_int = l_int + F.cross_entropy(lex_net(h3, text_i, s_all[p], spk), lex_t)
                l_int = l_int + F.mse_loss(sty_net(a3, text_i, ctx_z), z_t)
            parts["interp"] = l_int
        return self._total(parts, speech)

    def _total(self, parts: dict[str, Any], speech: Tensor) -> Tensor:
        """Sum of the stages' objectives in ``parts`` (the other entries are their terms, logged only)."""
        self.last_parts = {k: float(v.detach()) for k, v in parts.items()}
        total = sum((parts[k] for k in STAGE_LOSSES if k in parts), speech.new_zeros(()))
        if self.training and not total.requires_grad:  # nothing to learn in this batch (e.g. no words to contrast)
            total = total + speech.new_zeros((), requires_grad=True)
        return total

    def generator_losses(self, bl: Blocks, a_low: Tensor, s_all: Tensor, idx: Tensor) -> dict[str, Tensor]:
        """Eq. 9 (``"gen"``, with its parts for the log) on the generator's rollout over each window plus inserted
        silent blocks.

        Rollout (as the authors' code trains): each window's first block is the ground-truth context; every later
        sample block is generated from the previous *generated* block with the decoder's LSTM state carried over
        (:meth:`rollout`), so training sees the run-time chain and its drift. Inserted silent blocks (§6.4.1):
        after empty-word blocks, noise audio, z = 0, the nearest silent lexeme, the previous block's last pose held
        still; the paper inserts runs of 0-10 silent blocks and a block inside a run follows another silent block,
        so :data:`SILENT_RUN_LATER` of the inserted blocks get the held pose as their previous block too (one
        block each, fresh state)."""
        c = self.config
        p, i, n = bl.prev, bl.cur, bl.nxt
        a3 = torch.cat([a_low[p], a_low[i], a_low[n]], dim=2)  # (S, K, 3 d_a)
        target = bl.poses[i]
        z = self.block_styles(bl.style_row[i])  # (S, d_z) the blocks' learnable codes, trained with G (§5.3)
        s = s_all[i]
        n_real = i.numel()
        gen = self.rollout(bl.poses[p[:: bl.per_window]], a3, s, z, bl.per_window)  # (S, K, P)
        prev_m = bl.poses[p]
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
        if prev_m.shape[0] > n_real:  # the inserted silent blocks, one step each from their held pose
            extra, _ = self.gen(prev_m[n_real:], a3[n_real:], s[n_real:], z[n_real:])
            gen = torch.cat([gen, extra])  # (S', K, P)
        l_rec = F.mse_loss(gen, target)
        l_perc = F.mse_loss(self.vq.encode(gen, frozen=True), self.vq.encode(target, frozen=True).detach())
        perm = torch.randperm(n_real, device=a_low.device)  # eq. 12: same lexeme, another block's other inputs
        other, _ = self.gen(prev_m[:n_real][perm], a3[:n_real][perm], s[:n_real], z[:n_real][perm])
        l_lex = F.mse_loss(self.vq.encode(other, frozen=True), s[:n_real])
        zr = z[:n_real]
        mu, var = zr.mean(0), zr.var(0, unbiased=False) + 1e-6
        l_z = 0.5 * (mu**2 + var - var.log() - 1.0).mean()  # eq. 14 on the batch statistics
        l_gen = c.w_rec * l_rec + c.w_perc * l_perc + c.w_lexeme * l_lex + c.w_z * l_z
        return {"gen": l_gen, "rec": l_rec, "perc": l_perc, "lexeme": l_lex, "kl": l_z}

    def rollout(self, first_prev: Tensor, a3: Tensor, s: Tensor, z: Tensor, per_window: int) -> Tensor:
        """Generate each window's sample blocks one after another from its ground-truth context block.

        Parameters
        ----------
        first_prev : Tensor [shape=(B, K, P)]
            Each window's first (context) block.
        a3, s, z : Tensor [shape=(S, ...)]
            Per sample block (``S = B * per_window``, window by window): audio of blocks i-1, i, i+1, lexeme, style.

        Returns
        -------
        Tensor [shape=(S, K, P)]
            Block ``j`` of a window is generated from block ``j - 1``'s output and LSTM state.
        """
        b = first_prev.shape[0]
        view = lambda x: x.reshape(b, per_window, *x.shape[1:])  # noqa: E731  (S, ...) -> (B, W - 2, ...)
        a3, s, z = view(a3), view(s), view(z)
        prev, state, outs = first_prev, None, []
        for j in range(per_window):
            prev, state = self.gen(prev, a3[:, j], s[:, j], z[:, j], state)
            outs.append(prev)
        return torch.stack(outs, dim=1).flatten(0, 1)  # (B, W - 2, K, P) -> (S, K, P)
