"""Free-running generation (eq. 15): the one block loop of inference and of the validation that picks ``best.pt``.

Every block's lexeme comes from the lexeme interpreter (eq. 16, with the speaker), its style code from the style
interpreter (eq. 19), and its motion from the generator fed its own previous block, starting from the mean pose;
nothing of the target motion is used. :meth:`RhythmicGenerator.generate_blocks` runs it on one speech,
:meth:`RhythmicSpec.validation_loss` on a batch of held-out windows and scores it with :func:`free_running_score`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from robogest.generators.learned.rhythmic.model import Blocks, RhythmicNet, torch

if TYPE_CHECKING:
    from torch import Tensor
    from torch.nn import Module

#: Weight of the speed term in :func:`free_running_score`.
SPEED_WEIGHT = 1.0


@dataclass
class BlockInputs:
    """Per-block run-time inputs of ``B`` sequences of ``C`` blocks (tensors).

    ``a3`` ``(B, C, K, 3 d_a)`` and ``h3`` ``(B, C, K, 3 d_A)``: ``a_low`` / ``a_high`` of blocks i-1, i, i+1;
    ``text`` ``(B, C, K, D)`` (scaled); ``silent`` ``(B, C)`` bool; ``with_text`` ``(B,)`` bool (the sequence has
    words: the interpreters with text, else the audio-only ones, §6.3); ``speaker`` ``(B,)`` long.
    """

    a3: Tensor
    h3: Tensor
    text: Tensor
    silent: Tensor
    with_text: Tensor
    speaker: Tensor


def _either(with_text: Tensor, net_text: Module, net_audio: Module, *args: Tensor | None) -> Tensor:
    """Run the text or the audio-only interpreter per sequence (only the one(s) needed)."""
    if bool(with_text.all()):
        text_out: Tensor = net_text(*args)
        return text_out
    if not bool(with_text.any()):
        audio_out: Tensor = net_audio(*args)
        return audio_out
    return torch.where(with_text[:, None], net_text(*args), net_audio(*args))


def _lexemes(
    net: RhythmicNet, inp: BlockInputs, j: int, s_prev: Tensor, temperature: float, generator: torch.Generator | None
) -> Tensor:
    """Block ``j``'s lexeme indices ``(B,)`` from the lexeme interpreter: most likely, or sampled (temperature)."""
    logits = _either(inp.with_text, net.lex_interp, net.lex_interp_audio, inp.h3[:, j], inp.text[:, j], s_prev,
                     inp.speaker)  # fmt: skip
    if temperature > 0:
        p = torch.softmax(logits / temperature, dim=1)
        return torch.multinomial(p.cpu(), 1, generator=generator)[:, 0].to(logits.device)
    return logits.argmax(dim=1)


def free_run(
    net: RhythmicNet,
    inp: BlockInputs,
    lexemes: Tensor | None = None,
    styles: Tensor | None = None,
    force_silent: bool = True,
    temperature: float = 0.0,
    generator: torch.Generator | None = None,
) -> tuple[Tensor, Tensor]:
    """Generate ``C`` blocks of each sequence one after another, as at run time.

    Parameters
    ----------
    net : RhythmicNet
    inp : BlockInputs
    lexemes : Tensor [shape=(B, C)], long, optional
        Force these lexemes (silent blocks are then not forced to a silent lexeme).
    styles : Tensor [shape=(B, C, d_z)], optional
        Force these style codes.
    force_silent : bool
        The silent-period hint (§6.4.1): silent blocks get the silent lexeme nearest the previous one and z = 0.
    temperature : float
        0: the most likely lexeme; > 0: a sample of the interpreter's softmax at this temperature.
    generator : torch.Generator, optional
        Random source of those samples.

    Returns
    -------
    blocks : Tensor [shape=(B, C, K, P)]
        Normalised motion blocks.
    lexeme_ids : Tensor [shape=(B, C)], long
    """
    c = net.config
    b, n_c = inp.a3.shape[:2]
    dev = inp.a3.device
    codebook = net.vq.codebook.detach()
    prev = torch.zeros(b, c.block, c.n_pose, device=dev)  # the mean pose (normalised zeros)
    s_prev = codebook[net.vq.quantize(net.vq.encode(prev))]  # (B, d_s)
    z_prev = torch.zeros(b, c.style_dim, device=dev)
    out, ids, state = [], [], None
    for j in range(n_c):
        silent = inp.silent[:, j]
        if lexemes is not None:
            lex = lexemes[:, j]
        else:
            lex = _lexemes(net, inp, j, s_prev, temperature, generator)
            if force_silent:
                forced = net.nearest_silent(s_prev)
                lex = torch.where(silent & (forced >= 0), forced, lex)
        s = codebook[lex]  # (B, d_s)
        if styles is not None:
            z = styles[:, j]
        else:
            ctx = torch.cat([z_prev, s], dim=1)
            z = _either(inp.with_text, net.style_interp, net.style_interp_audio, inp.a3[:, j], inp.text[:, j], ctx)
            if lexemes is None and force_silent:
                z = torch.where(silent[:, None], torch.zeros_like(z), z)  # silent blocks: z = 0 (§6.4.1)
        prev, state = net.gen(prev, inp.a3[:, j], s, z, state)  # (B, K, P), LSTM state carried over
        out.append(prev)
        ids.append(lex)
        s_prev, z_prev = s, z
    return torch.stack(out, dim=1), torch.stack(ids, dim=1)


def window_inputs(net: RhythmicNet, bl: Blocks) -> BlockInputs:
    """The run-time inputs of the sample blocks of training-format windows (:meth:`RhythmicNet.segment`).

    Each window's first and last block are only the neighbours of the audio context, as in training; a window
    uses the interpreters with text when any of its sample blocks has words.
    """
    a_low, a_high, _ = net.audio_features(bl.mel)
    p, i, n = bl.prev, bl.cur, bl.nxt
    w = bl.per_window

    def view(x: Tensor) -> Tensor:  # (S, ...) -> (B, W - 2, ...)
        return x.reshape(-1, w, *x.shape[1:])

    text = view(bl.text[i])  # (B, W - 2, K, D)
    return BlockInputs(
        a3=view(torch.cat([a_low[p], a_low[i], a_low[n]], dim=2)),
        h3=view(torch.cat([a_high[p], a_high[i], a_high[n]], dim=2)),
        text=text,
        silent=view(bl.empty[i]),
        with_text=(text.amax(dim=(1, 2, 3)) > -1.0 + 1e-3),
        speaker=view(bl.speaker[i])[:, 0],
    )


def free_running_score(generated: Tensor, target: Tensor) -> Tensor:
    """The selection objective: MSE of the poses plus :data:`SPEED_WEIGHT` x the squared error of each pose
    channel's RMS speed.

    Why: free-running, the model chooses its own lexemes, so it cannot match the take frame by frame, and the MSE
    alone is lowest for a still mean pose (MAJE's blind spot: the held-out benchmark found the still mean pose
    beats replayed real motion). The paper scores MAJE (position error) beside MAD (acceleration difference) and
    FGD (distribution); the speed term is the cheap distribution part, penalising motion that is too still or too
    busy whatever its phase. Both on the normalised exp-map channels (each in units of its training spread, the
    space of eq. 10's reconstruction loss): the trainer's validation hook has no normalisation to go to joint
    positions.

    Parameters
    ----------
    generated, target : Tensor [shape=(B, C, K, P)]
        Normalised motion blocks of ``B`` sequences.

    Returns
    -------
    Tensor [shape=()]
    """
    g, t = generated.flatten(1, 2), target.flatten(1, 2)  # (B, C, K, P) -> (B, C * K, P)

    def speed(x: Tensor) -> Tensor:  # (B, T, P) -> (B, P) RMS of the frame differences
        return x.diff(dim=1).pow(2).mean(dim=1).sqrt()

    return (g - t).pow(2).mean() + SPEED_WEIGHT * (speed(g) - speed(t)).pow(2).mean()
