"""Shared fixtures: a tiny synthetic dataset and one short training run reused by several tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from robogest.data import make_fixture_dataset

#: A reduced Gesticulator (same structure, narrower layers) so the overfit run fits the test time budget on
#: two CPU cores; the paper's sizes are checked separately in test_gesticulator.py.
SMALL_MODEL = {"frame_dim": 32, "hidden": (128, 64), "cond_dim": 64}
HASH16 = {"text_encoder": "hash-test", "text_encoder_kwargs": {"dim": 16}}
#: A reduced Rhythmic Gesticulator (the paper's structure, narrower layers) for the same reason; the paper's widths
#: are the defaults, checked in test_rhythmic.test_paper_widths_are_the_defaults.
RHYTHMIC_SMALL = {
    "hidden": 64, "audio_channels": 32, "audio_layers": 4, "vq_channels": 32, "lexicon_size": 12, "lexeme_dim": 32,
    "motion_feat_dim": 32, "audio_feat_dim": 32, "style_dim": 8, "pe_dim": 8, "latent_groups": 8, "latent_classes": 32,
}  # fmt: skip
#: Epochs of the shared run: 7 without autoregression + the 4 annealing epochs + 4 with full teacher forcing.
EPOCHS = 15


@pytest.fixture(scope="session", autouse=True)
def _one_torch_thread():
    """Tiny models train faster on one thread, and two threads on two busy cores can stall for seconds."""
    try:
        import torch
    except ImportError:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def fixture_data(tmp_path_factory) -> Path:
    return make_fixture_dataset(tmp_path_factory.mktemp("ds") / "pairs", n_takes=3, duration_s=8.0, seed=1)


@pytest.fixture(scope="session")
def trained(fixture_data, tmp_path_factory):
    """``(TrainConfig, best checkpoint path)`` after a short overfit run on all takes (no validation split)."""
    pytest.importorskip("torch")
    from robogest.generators.learned import train_model
    from robogest.learn.trainer import TrainConfig

    out = tmp_path_factory.mktemp("run")
    cfg = TrainConfig(
        data=str(fixture_data),
        out=str(out),
        epochs=EPOCHS,
        lr=2e-3,
        batch_size=32,
        window_stride=2,
        val_fraction=0.0,
        device="cpu",
        cache_dir=str(out / "cache"),
        model_overrides=SMALL_MODEL,
        **HASH16,
    )
    best = train_model(cfg, log=lambda s: None)
    return cfg, best
