"""Speech2AffectiveGestures (Bhattacharya et al., ACM MM 2021): ``skeleton`` (pose graph, edge directions) and
``config`` (inputs, hyper-parameters), numpy only; ``networks``, ``training`` (the trainer's spec and losses),
``inference`` (the checkpoint generator). Importing this package needs PyTorch."""

from robogest.data.datasets import speaker_key
from robogest.generators.learned.s2ag.config import S2AGConfig, mfcc_from_mel
from robogest.generators.learned.s2ag.inference import S2AGGenerator
from robogest.generators.learned.s2ag.networks import AffectiveEncoder, S2AGDiscriminator, S2AGGeneratorNet, S2AGNet
from robogest.generators.learned.s2ag.skeleton import (
    BODY_PARTS,
    BONE_LENGTHS,
    EDGES,
    JOINTS,
    TEMPORAL_REACH,
    directions_to_motion,
    directions_to_positions,
    edge_adjacency,
    expmaps_to_directions,
    motion_to_directions,
    part_adjacency,
)
from robogest.generators.learned.s2ag.training import SPEC, S2AGSpec, split_batch

__all__ = [
    "BODY_PARTS",
    "BONE_LENGTHS",
    "EDGES",
    "JOINTS",
    "SPEC",
    "TEMPORAL_REACH",
    "AffectiveEncoder",
    "S2AGConfig",
    "S2AGDiscriminator",
    "S2AGGenerator",
    "S2AGGeneratorNet",
    "S2AGNet",
    "S2AGSpec",
    "directions_to_motion",
    "directions_to_positions",
    "edge_adjacency",
    "expmaps_to_directions",
    "mfcc_from_mel",
    "motion_to_directions",
    "part_adjacency",
    "speaker_key",
    "split_batch",
]
