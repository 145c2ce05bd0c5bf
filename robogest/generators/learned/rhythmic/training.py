"""The trainer's view of the Rhythmic Gesticulator (:class:`robogest.learn.trainer.ModelSpec`): staged epochs and
beat-block windows."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from robogest.data.datasets import speaker_key
from robogest.data.features import FeatureConfig
from robogest.data.prep import slice_windows
from robogest.errors import InputError
from robogest.generators.learned.rhythmic.cache import take_rhythm_blocks
from robogest.generators.learned.rhythmic.config import STAGES, RhythmicConfig
from robogest.generators.learned.rhythmic.model import RhythmicNet
from robogest.generators.learned.rhythmic.networks import AUDIO_ENCODERS
from robogest.generators.learned.rhythmic.take import take_blocks
from robogest.learn import config_with_overrides
from robogest.learn.spec import ModelSpec


class RhythmicSpec(ModelSpec[RhythmicConfig]):
    """The trainer's view of the model (:class:`robogest.learn.trainer.ModelSpec`)."""

    name = "rhythmic"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> RhythmicConfig:
        front = FeatureConfig().speech_config()  # the trainer's feature front-end: its rate and mel analysis
        fixed = {"n_acoustic": n_acoustic, "n_text": n_text, "n_pose": n_pose, "n_mels": front.n_mels,
                 "audio_sr": front.sr, "mel_window_s": front.mel_window_s, "fps": front.fps}  # fmt: skip
        return config_with_overrides(RhythmicConfig, "rhythmic", overrides, **fixed)

    def config_from_dict(self, d: dict[str, Any]) -> RhythmicConfig:
        return RhythmicConfig.from_dict(d)

    def fit_config(self, config: RhythmicConfig, takes) -> RhythmicConfig:
        """The speaker table of the training takes (:func:`robogest.data.speaker_key`)."""
        return dataclasses.replace(config, speakers=tuple(sorted({speaker_key(t.name) for t in takes})))

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

    def make_windows(self, takes, norm, config: RhythmicConfig, length: int, stride: int, store=None, cache_dir=None):
        """Windows of ``length // K`` consecutive beat blocks of each whole take (:func:`take_blocks`).

        Beats and silent blocks are found once on the whole take, as at run time on the whole speech. The audio
        blocks come from each take's recording, time-scaled and re-analysed (a take without ``audio_path``: from
        its log-mel frames). Consecutive windows start about ``stride`` frames apart (``stride`` over the take's
        mean clip length, in blocks). ``store``: :func:`slice_windows`. ``cache_dir``: where each take's beats and
        time-scaled audio blocks are kept for later runs (:func:`.cache.take_rhythm_blocks`; None: not kept).

        Returns
        -------
        x : LazyWindows [shape=(N, W * K, n_mels + D + 2)], float32
            Standardised time-scaled log-mel, raw text, silent-block flag, speaker index (``config.speakers``);
            block ``w`` is frames ``[w K, (w + 1) K)``.
        y : ndarray [shape=(N, W * K, P)], float32
            Normalised poses.
        take_index : ndarray [shape=(N,)], int
        """
        k, m = config.block, config.n_mels
        w = length // k
        f = m + config.n_text + 2
        table = {s: j for j, s in enumerate(config.speakers)}

        def per_take():  # one take's blocks at a time: (index, (C, K * F), (C, K * P), stride in blocks)
            for i, t in enumerate(takes):
                beats, tsm_db = None, None  # no recording: beats and blocks of the log-mel frames
                if t.audio_path is not None:  # beats by the speech front-end's rule, blocks time-scaled
                    beats, tsm_db = take_rhythm_blocks(t, config, cache_dir)
                tb = take_blocks(t.acoustic[:, :m], t.text, norm, config, None, t.poses, beats, tsm_db)
                n_c = tb.silent.shape[0]
                flag = np.broadcast_to(tb.silent[:, None, None], (n_c, k, 1))
                spk = np.full((n_c, k, 1), table.get(speaker_key(t.name), 0), np.float32)  # unseen speaker -> 0
                x = np.concatenate([tb.mel, tb.text, flag, spk], axis=2).reshape(n_c, -1)  # (C, K, F) -> (C, K * F)
                yield i, x, tb.poses.reshape(n_c, -1), max(1, round(stride * n_c / t.n_frames))  # frames -> blocks

        # a window of W blocks of K * F values is read as (W * K, F)
        return slice_windows(
            per_take(), w, 1, k * f, k * config.n_pose, (w * k, f), (w * k, config.n_pose), store=store
        )

    def warm_cache(self, takes, config: RhythmicConfig, cache_dir, rank: int, world_size: int) -> None:
        """Beats and time-scaled blocks of takes ``rank``, ``rank + world_size``, ... into ``cache_dir``
        (:func:`.cache.take_rhythm_blocks`): the ranks share the slow part of :meth:`make_windows`."""
        for t in takes[rank::world_size]:
            if t.audio_path is not None:
                take_rhythm_blocks(t, config, cache_dir)

    def before_step(self, model, speech, poses, epoch: int, config: RhythmicConfig, sync=None) -> None:
        """Codebook upkeep and silent-lexeme statistics, the same on every rank (:meth:`RhythmicNet.before_step`)."""
        model.before_step(speech, poses, epoch, sync)

    def loss(self, model, speech, poses, epoch: int, config: RhythmicConfig):
        return model(speech, poses, epoch)  # through the (possibly DDP) wrapper's forward


SPEC = RhythmicSpec()
