"""The trainer's view of the Rhythmic Gesticulator (:class:`robogest.learn.spec.ModelSpec`): staged epochs and
beat-block windows."""

from __future__ import annotations

import dataclasses
import itertools
import os
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.data.datasets import Take, speaker_key
from robogest.data.features import FeatureConfig
from robogest.data.prep import LazyWindows, Normalization, slice_windows
from robogest.errors import InputError
from robogest.generators.learned.rhythmic.cache import take_rhythm_blocks
from robogest.generators.learned.rhythmic.config import STAGES, RhythmicConfig, style_row_count
from robogest.generators.learned.rhythmic.freerun import free_run, free_running_score, window_inputs
from robogest.generators.learned.rhythmic.model import RhythmicNet
from robogest.generators.learned.rhythmic.networks import AUDIO_ENCODERS
from robogest.generators.learned.rhythmic.take import take_blocks
from robogest.generators.learned.speech_encoder import load_speech_encoder
from robogest.learn import config_with_overrides
from robogest.learn.spec import ModelSpec

if TYPE_CHECKING:
    from torch import Tensor

    from robogest.learn.dist import Sync


class RhythmicSpec(ModelSpec[RhythmicConfig]):
    """The trainer's view of the model (:class:`robogest.learn.spec.ModelSpec`)."""

    name = "rhythmic"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> RhythmicConfig:
        front = FeatureConfig().speech_config()  # the trainer's feature front-end: its rate and mel analysis
        fixed = {"n_acoustic": n_acoustic, "n_text": n_text, "n_pose": n_pose, "n_mels": front.n_mels,
                 "audio_sr": front.sr, "mel_window_s": front.mel_window_s, "fps": front.fps}  # fmt: skip
        config: RhythmicConfig = config_with_overrides(RhythmicConfig, "rhythmic", overrides, **fixed)
        if config.speech_encoder:  # loaded (and checked) before any training; its width sizes the blocks
            config = dataclasses.replace(config, speech_dim=load_speech_encoder(config.speech_encoder).dim)
        return config

    def config_from_dict(self, d: dict[str, Any]) -> RhythmicConfig:
        """A checkpoint's config (``--resume``); one from before the per-block style codes is an InputError."""
        try:
            return RhythmicConfig.from_dict(d)
        except ValueError as e:
            raise InputError(f"--resume: {e}") from None

    def fit_config(self, config: RhythmicConfig, takes: Sequence[Take]) -> RhythmicConfig:
        """The speaker table of the training takes (:func:`robogest.data.speaker_key`) and their style-code rows
        (one learnable code per training block, :func:`.config.style_row_count` rows reserved per take).

        Raises
        ------
        InputError
            Two training takes share a name (their blocks' style codes are found by take name).
        """
        names = [t.name for t in takes]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise InputError(f"training takes named {', '.join(dup)} twice; give every take its own file name")
        rows = np.cumsum([0] + [style_row_count(t.n_frames, config) for t in takes])
        return dataclasses.replace(
            config,
            speakers=tuple(sorted({speaker_key(t.name) for t in takes})),
            style_takes=tuple(names),
            style_rows=tuple(int(r) for r in rows),
        )

    def plan_epochs(self, config: RhythmicConfig, epochs: int) -> RhythmicConfig:
        """Give each stage its share of ``epochs`` (at least one each) when training sequentially.

        Raises
        ------
        InputError
            Fewer epochs than stages.
        """
        if config.stages == "joint":
            return config
        trainable = bool(AUDIO_ENCODERS[config.audio_encoder].trainable)  # a class attribute
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
        """``best.pt`` is chosen among the epochs from the generator stage on: from then on the model generates
        motion (before, the generator is untrained and free-running generation is noise). Interpreter-stage and
        generator-stage epochs compete on the same free-running score (:meth:`validation_loss`)."""
        return config.stage_ends[1] if config.stage_at(0) is not None else 0

    def validation_loss(self, model: Any, speech: Tensor, poses: Tensor, epoch: int, config: RhythmicConfig) -> Tensor:
        """Free-running score of held-out windows, what ``best.pt`` is chosen on (:func:`.freerun.free_running_score`).

        As inference generates (:func:`.freerun.free_run`): lexemes from the lexeme interpreter (with the window's
        speaker), style codes from the style interpreter, each block from the model's own previous block starting
        at the mean pose, the silent-period hint; the target motion is only the target. The same at every epoch, so
        generator-stage and interpreter-stage epochs compare (the teacher-forced :meth:`loss` of the stages
        does not: each stage's loss measures only its own part, with ground-truth lexemes and style codes).
        """
        net: RhythmicNet = getattr(model, "module", model)  # a DDP wrapper's model
        bl = net.segment(speech, poses)
        generated, _ = free_run(net, window_inputs(net, bl))  # (B, W - 2, K, P)
        target = bl.poses[bl.cur].reshape(generated.shape)
        return free_running_score(generated, target)

    def stage_name(self, epoch: int, config: RhythmicConfig) -> str:
        return config.stage_at(epoch) or "all stages"

    def build(self, config: RhythmicConfig) -> RhythmicNet:
        return RhythmicNet(config)

    def sequence_length(self, config: RhythmicConfig) -> int:
        return config.window_blocks * config.block

    def make_windows(
        self,
        takes: Sequence[Take],
        norm: Normalization,
        config: RhythmicConfig,
        length: int,
        stride: int,
        store: str | os.PathLike | None = None,
        cache_dir: str | os.PathLike | None = None,
    ) -> tuple[LazyWindows, LazyWindows, np.ndarray]:
        """Windows of ``length // K`` consecutive beat blocks of each whole take (:func:`take_blocks`).

        Beats and silent blocks are found once on the whole take, as at run time on the whole speech. The audio
        blocks come from each take's recording, time-scaled and re-analysed (a take without ``audio_path``: from
        its log-mel frames). Consecutive windows start about ``stride`` frames apart (``stride`` over the take's
        mean clip length, in blocks). ``store``: :func:`slice_windows`. ``cache_dir``: where each take's beats and
        time-scaled audio blocks are kept for later runs (:func:`.cache.take_rhythm_blocks`; None: not kept).

        Returns
        -------
        x : LazyWindows [shape=(N, W * K, n_mels + D + 3)], float32
            Standardised time-scaled log-mel, raw text, silent-block flag, speaker index (``config.speakers``),
            style-code row (``config.style_rows``; -1 for a take that is not a training take); block ``w`` is frames
            ``[w K, (w + 1) K)``.
        y : ndarray [shape=(N, W * K, P)], float32
            Normalised poses.
        take_index : ndarray [shape=(N,)], int
        """
        k, m = config.block, config.n_mels
        w = length // k
        f = config.n_audio + config.n_text + 3
        table = {s: j for j, s in enumerate(config.speakers)}
        style_rows = dict(zip(config.style_takes, itertools.pairwise(config.style_rows), strict=True))

        def per_take() -> Iterator[tuple[int, np.ndarray, np.ndarray, int]]:  # one take's blocks at a time
            # (index, (C, K * F), (C, K * P), stride in blocks)
            for i, t in enumerate(takes):
                beats, tsm_db = None, None  # no recording: beats and blocks of the log-mel frames
                if t.audio_path is not None:  # beats by the speech front-end's rule, blocks time-scaled
                    beats, tsm_db = take_rhythm_blocks(t, config, cache_dir)
                audio = t.read_audio(config.audio_sr) if config.speech_encoder and t.audio_path else None
                tb = take_blocks(t.acoustic[:, :m], t.text, norm, config, audio, t.poses, beats, tsm_db)
                if tb.poses is None:  # take_blocks returns poses when it is given them
                    raise InputError(f"take {t.name}: no poses")
                n_c = tb.silent.shape[0]
                flag = np.broadcast_to(tb.silent[:, None, None], (n_c, k, 1))
                spk = np.full((n_c, k, 1), table.get(speaker_key(t.name), 0), np.float32)  # unseen speaker -> 0
                rows = np.broadcast_to(_style_rows(t, n_c, style_rows.get(t.name))[:, None, None], (n_c, k, 1))
                x = np.concatenate([tb.mel, tb.text, flag, spk, rows], axis=2).reshape(n_c, -1)  # (C, K * F)
                yield i, x, tb.poses.reshape(n_c, -1), max(1, round(stride * n_c / t.n_frames))  # frames -> blocks

        # a window of W blocks of K * F values is read as (W * K, F)
        return slice_windows(
            per_take(), w, 1, k * f, k * config.n_pose, (w * k, f), (w * k, config.n_pose), store=store
        )

    def warm_cache(
        self, takes: Sequence[Take], config: RhythmicConfig, cache_dir: str | os.PathLike, rank: int, world_size: int
    ) -> None:
        """Beats and time-scaled blocks of takes ``rank``, ``rank + world_size``, ... into ``cache_dir``
        (:func:`.cache.take_rhythm_blocks`): the ranks share the slow part of :meth:`make_windows`."""
        for t in takes[rank::world_size]:
            if t.audio_path is not None:
                take_rhythm_blocks(t, config, cache_dir)

    def before_step(
        self, model: Any, speech: Tensor, poses: Tensor, epoch: int, config: RhythmicConfig, sync: Sync | None = None
    ) -> None:
        """Codebook upkeep and silent-lexeme statistics, the same on every rank (:meth:`RhythmicNet.before_step`)."""
        model.before_step(speech, poses, epoch, sync)

    def loss(self, model: Any, speech: Tensor, poses: Tensor, epoch: int, config: RhythmicConfig) -> Tensor:
        out: Tensor = model(speech, poses, epoch)  # through the (possibly DDP) wrapper's forward
        return out


def _style_rows(take: Take, n_blocks: int, span: tuple[int, int] | None) -> np.ndarray:
    """Style-code rows ``(C,)`` float32 of a take's blocks: its rows in ``span`` (start, end) of the table, or -1
    for a take without rows (a validation take: its style codes come from the interpreter).

    Raises
    ------
    InputError
        The take has more blocks than rows (beats closer than ``D_m``).
    """
    if span is None:
        return np.full(n_blocks, -1.0, np.float32)
    start, end = span
    if n_blocks > end - start:
        raise InputError(
            f"take {take.name}: {n_blocks} beat blocks but {end - start} style-code rows (beats closer than "
            "min_beat_gap_s); raise --set min_beat_gap_s or report the take"
        )
    return np.arange(start, start + n_blocks, dtype=np.float32)


SPEC = RhythmicSpec()
