"""Rhythmic Gesticulator inference: blocks at the speech's beats, lexemes and styles from the interpreters."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogest.data.features import expmap_to_motion, speech_inputs
from robogest.errors import InputError
from robogest.generators.learned.checkpoint import CheckpointGenerator
from robogest.generators.learned.rhythmic.blocks import denormalize_blocks, gaussian_smooth
from robogest.generators.learned.rhythmic.config import TEXT_SCALE, RhythmicConfig
from robogest.generators.learned.rhythmic.model import RhythmicNet, torch
from robogest.generators.learned.rhythmic.take import take_blocks
from robogest.motion.human_motion import HumanMotion
from robogest.speech.types import Speech


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

    def configure(self, lexeme_temperature: float | None = None, speaker: int | str | None = None) -> None:
        """``lexeme_temperature``: 0 the most likely lexeme, > 0 sample at that temperature; None: the config's.
        ``speaker``: index or key (e.g. BEAT2's ``"2"``) of a training speaker; None: the first."""
        if lexeme_temperature is not None and not lexeme_temperature >= 0:
            raise InputError(f"lexeme_temperature={lexeme_temperature!r}: must be >= 0 (0: the most likely lexeme)")
        self.temperature = lexeme_temperature
        known = list(self.config.speakers)
        if speaker is None:
            self.speaker_index = 0
        elif isinstance(speaker, str) and speaker in known:
            self.speaker_index = known.index(speaker)
        elif isinstance(speaker, int) and not isinstance(speaker, bool) and 0 <= speaker < len(known):
            self.speaker_index = speaker
        else:
            raise InputError(f"speaker {speaker!r} is not one of the model's speakers {known} (index or key)")

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
        tb = take_blocks(acoustic[:, : c.n_mels], text, self.norm, c, audio, beats_s=speech.beats_s)
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
            out, lex_ids, state = [], np.zeros(n_b, int), None
            spk = torch.full((1,), self.speaker_index, dtype=torch.long, device=dev)
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
                y, state = m.gen(prev, a3[j : j + 1], s, z, state, spk)  # (1, K, P), LSTM state carried over
                out.append(y[0])
                lex_ids[j] = lex
                prev, s_prev, z_prev = y, s, z
            blocks = torch.stack(out).cpu().numpy()  # (C, K, P)
        poses = denormalize_blocks(blocks, np.diff(bounds))  # (T, P), normalised
        poses = self.norm.pose_inverse(gaussian_smooth(poses, c.smooth_kernel))
        return BlockPlan(bounds, lex_ids, silent, poses)

    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion at ``speech.fps`` with exactly ``speech.n_frames`` frames.

        Each lexeme is the interpreter's most likely one (the paper), or, with a lexeme temperature > 0 (the
        ``lexeme_temperature`` option, else the checkpoint config's), sampled from its softmax at that temperature
        with a torch generator seeded by ``seed`` (the same seed gives the same motion, another seed other lexemes);
        silent blocks still get the silent lexeme. The Gumbel latent takes its most likely categories. The blocks'
        lexemes are kept in :attr:`annotations`.
        """
        s = self.at_model_rate(speech)
        g = torch.Generator().manual_seed(int(seed))
        temperature = self.config.lexeme_temperature if self.temperature is None else self.temperature
        plan = self.generate_blocks(s, temperature=temperature, generator=g)
        self._annotations = {  # for lexeme entropy (eq. 23) in `robogest eval`
            "lexemes": plan.lexemes.astype(np.int64),
            "n_lexemes": np.int64(self.config.lexicon_size),
            "block_bounds_s": plan.bounds / s.fps,
        }
        return expmap_to_motion(plan.poses, s.fps).resample(speech.fps, n_frames=speech.n_frames)
