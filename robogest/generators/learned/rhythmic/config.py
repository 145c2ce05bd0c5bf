"""Rhythmic Gesticulator hyper-parameters and constants (numpy only, so data preparation needs no torch)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from robogest.errors import InputError
from robogest.generators.learned.rhythmic.blocks import block_frames

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
        frames are quiet (:func:`.blocks.silent_blocks`).
    lexeme_temperature : float
        0 (default, the paper): :meth:`RhythmicGenerator.generate` takes the interpreter's most likely lexeme, so
        ``seed`` has no effect; > 0 (``--set lexeme_temperature=1`` at training, or the generator's
        ``lexeme_temperature`` option) samples each lexeme from its softmax at this temperature, seeded by ``seed``.
    smooth_kernel : int
        Gaussian kernel (frames) applied to the denormalised output.
    speakers : tuple of str
        Speaker keys (:func:`robogest.data.speaker_key` of the take names) in embedding order; filled from the
        training takes.
    speaker_dim : int
        Size of the learned speaker embedding the lexeme interpreters are conditioned on (eq. 16's one-hot speaker
        ID ``I`` through a linear layer, which an embedding is); 0: none. The generator (eq. 5) takes no speaker.
    style_takes, style_rows : tuple of str, tuple of int
        The learnable style codes ``{z_i}`` (§5.2-5.3), one row of :attr:`RhythmicNet.style_codes` per training
        block: take ``style_takes[t]``'s block ``c`` is row ``style_rows[t] + c`` (``style_rows[-1]`` rows in all,
        :func:`style_row_count` per take). Filled from the training takes by :meth:`RhythmicSpec.fit_config`.
    speech_encoder : str
        Folder of a local wav2vec2-family checkpoint (:mod:`robogest.generators.learned.speech_encoder`) whose last
        hidden layer becomes ``a_high`` (the paper's pretrained vq-wav2vec features); "" (default): none.
    speech_dim : int
        That encoder's feature size, filled from the checkpoint by ``RhythmicSpec.make_config``.
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
    lexeme_temperature: float = 0.0
    smooth_kernel: int = 5
    speakers: tuple = ("default",)
    speaker_dim: int = 8
    style_takes: tuple = ()
    style_rows: tuple = ()
    speech_encoder: str = ""
    speech_dim: int = 0

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
    def n_audio(self) -> int:
        """Audio columns of a block: the log-mel, then the pretrained speech encoder's features (if any)."""
        return self.n_mels + self.speech_dim

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

    @property
    def n_style_rows(self) -> int:
        """Rows of the style-code table (1 before :meth:`RhythmicSpec.fit_config` has filled the plan)."""
        return max(1, int(self.style_rows[-1])) if self.style_rows else 1

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RhythmicConfig:
        """The config of a checkpoint's ``model_config``.

        Raises
        ------
        ValueError
            A checkpoint from before the per-block style codes (it cannot load: retrain).
        """
        d = dict(d)
        if "style_rows" not in d:  # ValueError: the checkpoint loader names the file around it
            raise ValueError(
                "a Rhythmic Gesticulator checkpoint from before its per-block style codes and speaker-conditioned "
                "lexeme interpreter (eq. 16) cannot be loaded: retrain it with robogest train --model rhythmic"
            )
        for k in ("stage_weights", "stage_ends", "speakers", "style_takes", "style_rows"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)


def style_row_count(n_frames: int, c: RhythmicConfig) -> int:
    """Style-code rows reserved for a take of ``n_frames``: more than its beat blocks can number, since beats are
    at least ``D_m`` (``min_beat_gap_s``) apart, so clips are at least that long less a frame of rounding."""
    return n_frames // max(2, round(c.min_beat_gap_s * c.fps) - 1) + 2
