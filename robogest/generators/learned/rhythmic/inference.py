"""Rhythmic Gesticulator inference: blocks at the speech's beats, lexemes and styles from the interpreters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robogest.data.features import expmap_to_motion, speech_inputs
from robogest.errors import InputError
from robogest.generators.learned.checkpoint import CheckpointGenerator
from robogest.generators.learned.rhythmic.blocks import denormalize_blocks, gaussian_smooth
from robogest.generators.learned.rhythmic.config import TEXT_SCALE, RhythmicConfig
from robogest.generators.learned.rhythmic.freerun import BlockInputs, free_run
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

    def configure(
        self, lexeme_temperature: float | None = None, speaker: int | str | None = None, **options: Any
    ) -> None:
        """``lexeme_temperature``: 0 the most likely lexeme, > 0 sample at that temperature; None: the config's.
        ``speaker``: index or key (e.g. BEAT2's ``"2"``) of a training speaker; None: the first. Any other option
        is refused (:meth:`CheckpointGenerator.configure`)."""
        super().configure(**options)
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
        generator: torch.Generator | None = None,
    ) -> BlockPlan:
        """Blocks at the beats of :func:`take_rhythm`, lexemes/styles from the interpreters (or given), motion
        denormalised: :func:`.freerun.free_run` on the whole speech (the loop validation scores too).

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
        c, m, norm = self.config, self.model, self.norm
        if norm is None:
            raise InputError("the rhythmic generator has no normalisation statistics (pass norm= to from_model)")
        t_frames = speech.n_frames
        acoustic, text = speech_inputs(speech, self.features, self.encoder)  # (T, 69), (T, D)
        audio = None
        if c.audio_tsm or c.speech_encoder:  # the recording: time-scaled blocks, pretrained speech features
            from robogest.speech.audio import resample

            audio = resample(speech.audio, speech.sr, c.audio_sr)
        tb = take_blocks(acoustic[:, : c.n_mels], text, norm, c, audio, beats_s=speech.beats_s)
        bounds, silent = tb.bounds, tb.silent  # (C + 1,), (C,)
        n_b = len(bounds) - 1
        if n_b == 0 or t_frames == 0:
            return BlockPlan(bounds, np.zeros(0, int), np.zeros(0, bool), np.zeros((0, c.n_pose), np.float32))
        blk = torch.from_numpy(np.concatenate([tb.mel, tb.text / TEXT_SCALE], axis=2).astype(np.float32))
        dev = self.device
        with torch.inference_mode():
            b = blk.to(dev)  # (C, K, M + D)
            mel, txt = b[..., : c.n_audio], b[..., c.n_audio :]
            a_low, a_high, _ = m.audio_features(mel)  # (C, K, d_a), (C, K, d_A)
            ip, inx = np.maximum(np.arange(n_b) - 1, 0), np.minimum(np.arange(n_b) + 1, n_b - 1)
            inp = BlockInputs(
                a3=torch.cat([a_low[ip], a_low, a_low[inx]], dim=2)[None],  # (1, C, K, 3 d_a)
                h3=torch.cat([a_high[ip], a_high, a_high[inx]], dim=2)[None],  # (1, C, K, 3 d_A)
                text=txt[None],
                silent=torch.from_numpy(silent).to(dev)[None],
                with_text=torch.tensor([len(speech.words) > 0], device=dev),
                speaker=torch.full((1,), self.speaker_index, dtype=torch.long, device=dev),
            )
            forced_lex = None if lexemes is None else torch.as_tensor(np.asarray(lexemes), device=dev)[None].long()
            forced_z = None if styles is None else torch.as_tensor(styles, dtype=torch.float32, device=dev)[None]
            out, ids = free_run(m, inp, forced_lex, forced_z, force_silent, temperature, generator)
            blocks, lex_ids = out[0].cpu().numpy(), ids[0].cpu().numpy().astype(int)  # (C, K, P), (C,)
        poses = denormalize_blocks(blocks, np.diff(bounds))  # (T, P), normalised
        poses = norm.pose_inverse(gaussian_smooth(poses, c.smooth_kernel))
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
