"""Rhythmic Gesticulator (Ao et al., SIGGRAPH Asia 2022): ``config`` and ``blocks``/``take`` (beat blocks, numpy
only), ``networks`` and ``model`` (the learned parts and their losses), ``training`` (the trainer's spec),
``inference`` (the checkpoint generator). Importing this package needs PyTorch."""

from robogest.generators.learned.rhythmic.config import STAGES, RhythmicConfig
from robogest.generators.learned.rhythmic.inference import BlockPlan, RhythmicGenerator
from robogest.generators.learned.rhythmic.model import RhythmicNet
from robogest.generators.learned.rhythmic.networks import MotionVQ
from robogest.generators.learned.rhythmic.take import take_blocks, take_rhythm
from robogest.generators.learned.rhythmic.training import SPEC, RhythmicSpec

__all__ = [
    "SPEC",
    "STAGES",
    "BlockPlan",
    "MotionVQ",
    "RhythmicConfig",
    "RhythmicGenerator",
    "RhythmicNet",
    "RhythmicSpec",
    "take_blocks",
    "take_rhythm",
]
