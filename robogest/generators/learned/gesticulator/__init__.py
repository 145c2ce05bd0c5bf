"""Gesticulator (Kucherenko et al., ICMI 2020): ``model`` (config + network + loss), ``training`` (the trainer's
spec), ``inference`` (the checkpoint generator). Importing it needs PyTorch."""

from robogest.generators.learned.gesticulator.inference import GesticulatorGenerator
from robogest.generators.learned.gesticulator.model import (
    GesticulatorConfig,
    GesticulatorNet,
    gesture_loss,
    teacher_forcing_period,
    uses_ground_truth,
)
from robogest.generators.learned.gesticulator.training import SPEC, GesticulatorSpec

__all__ = [
    "SPEC",
    "GesticulatorConfig",
    "GesticulatorGenerator",
    "GesticulatorNet",
    "GesticulatorSpec",
    "gesture_loss",
    "teacher_forcing_period",
    "uses_ground_truth",
]
