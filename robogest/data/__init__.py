"""Speech-gesture datasets for the learned generators: readers, feature cache, splits, normalisation, fixtures.

Needs only numpy (and the speech/motion front-ends); torch is not imported here.
"""

from robogest.data.datasets import (
    Take,
    TakeFiles,
    compute_take,
    default_cache_dir,
    detect_layout,
    discover_takes,
    load_dataset,
    load_take,
    official_split,
    speaker_key,
)
from robogest.data.features import FeatureConfig, expmap_to_motion, motion_to_expmap, speech_inputs
from robogest.data.fixtures import make_fixture_dataset
from robogest.data.prep import Normalization, make_windows, split_takes

__all__ = [
    "FeatureConfig",
    "Normalization",
    "Take",
    "TakeFiles",
    "compute_take",
    "default_cache_dir",
    "detect_layout",
    "discover_takes",
    "expmap_to_motion",
    "load_dataset",
    "load_take",
    "make_fixture_dataset",
    "make_windows",
    "motion_to_expmap",
    "official_split",
    "speaker_key",
    "speech_inputs",
    "split_takes",
]
