"""Gesticulator's PCA option (§5.1: PCA keeping 95 % of the training poses' variance; off by default, as the
paper's final model): fitted on the training split only, stored in the checkpoint, applied at inference."""

from __future__ import annotations

import numpy as np
import pytest

from tests.generators.learned.conftest import HASH16, SMALL_MODEL

torch = pytest.importorskip("torch")

from robogest.generators.learned.gesticulator import GesticulatorConfig, GesticulatorNet  # noqa: E402
from robogest.generators.learned.gesticulator.pca import fit_pose_pca, variance_kept  # noqa: E402


def _poses(n: int = 400, p: int = 6, seed: int = 0) -> np.ndarray:
    """``(n, p)`` zero-mean poses whose variance falls off per axis (a few axes carry most of it)."""
    rng = np.random.default_rng(seed)
    mix = np.linalg.qr(rng.standard_normal((p, p)))[0]  # (p, p) rotation: the axes are not the coordinates
    x = rng.standard_normal((n, p)) * np.array([3.0, 2.0, 1.0, 0.3, 0.1, 0.05])[:p]
    x = x @ mix.T
    return x - x.mean(0)


def test_pca_off_by_default_as_the_paper_final_model():
    c = GesticulatorConfig()
    assert c.pca_variance == 0.0 and c.pca_components == () and c.n_out == c.n_pose
    assert GesticulatorNet(c).pca_basis is None


@pytest.mark.parametrize("variance", [0.5, 0.95, 0.999])
def test_variance_kept_reaches_the_threshold_with_the_fewest_components(variance):
    x = _poses()
    comps, kept = fit_pose_pca(np.array_split(x, 3), variance)  # chunked: one take at a time
    assert comps.shape[1] == 6 and 1 <= comps.shape[0] <= 6
    np.testing.assert_allclose(comps @ comps.T, np.eye(comps.shape[0]), atol=1e-9)  # orthonormal rows
    assert variance_kept(comps, x) >= variance
    assert kept == pytest.approx(variance_kept(comps, x), abs=1e-9)
    if comps.shape[0] > 1:  # one component fewer would not have kept enough
        assert variance_kept(comps[:-1], x) < variance


def test_round_trip_through_the_output_space():
    """Poses in the PCA subspace survive pose -> coefficients -> pose exactly; others lose only their residual."""
    x = _poses()
    comps, _ = fit_pose_pca([x], 0.95)
    k = comps.shape[0]
    assert k < 6
    cfg = GesticulatorConfig(
        n_acoustic=4, n_text=3, n_pose=6, pca_variance=0.95, pca_components=tuple(map(tuple, comps.tolist()))
    )
    net = GesticulatorNet(cfg).eval()
    assert cfg.n_out == k and net.output.out_features == k and net.pose_encoder[0].in_features == 3 * k
    coef = torch.randn(5, k)
    torch.testing.assert_close(net.to_output_space(net.from_output_space(coef)), coef, atol=1e-5, rtol=0)
    poses = torch.from_numpy(x[:50].astype(np.float32))
    back = net.from_output_space(net.to_output_space(poses))
    resid = float(((back - poses) ** 2).sum() / (poses**2).sum())
    assert resid <= 0.1  # at most the 5 % of variance left out, on a sample
    speech = torch.randn(2, cfg.sequence_length, cfg.n_input)
    for period in (None, 1):  # whatever the mode, the network answers full poses
        assert net(speech, None, period).shape == (2, cfg.train_frames, 6)


def test_pca_variance_without_components_is_refused():
    with pytest.raises(ValueError, match=r"no pca_components: fit them"):
        GesticulatorNet(GesticulatorConfig(n_acoustic=4, n_text=3, n_pose=6, pca_variance=0.95))
    with pytest.raises(ValueError, match=r"pca_variance=1\.5"):
        GesticulatorConfig(pca_variance=1.5)
    with pytest.raises(ValueError, match=r"n_pose=6"):
        GesticulatorConfig(n_acoustic=4, n_text=3, n_pose=6, pca_variance=0.9, pca_components=((1.0, 0.0),))


def test_trained_pca_is_fitted_on_the_training_split_stored_and_applied(fixture_data, tmp_path, monkeypatch):
    """``--set pca_variance=0.95``: the basis is fitted on the training takes' frames only (the validation take's
    never reach it), stored in the checkpoint, loaded into a generator whose network predicts that many
    coefficients, and generation gives full poses."""
    from robogest.data import FeatureConfig
    from robogest.data.datasets import load_dataset
    from robogest.data.prep import Normalization, split_takes
    from robogest.generators.learned import train_model
    from robogest.generators.learned.gesticulator import GesticulatorGenerator
    from robogest.generators.learned.gesticulator import training as gesticulator_training
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig
    from robogest.speech import synthesize

    seen: list[np.ndarray] = []

    def spy(chunks, variance):
        seen.extend(np.asarray(c) for c in chunks)
        return fit_pose_pca(seen, variance)

    monkeypatch.setattr(gesticulator_training, "fit_pose_pca", spy)
    cfg = TrainConfig(
        data=str(fixture_data), out=str(tmp_path / "o"), epochs=2, lr=1e-3, batch_size=64, window_stride=10,
        val_fraction=0.34, device="cpu", cache_dir=str(tmp_path / "cache"),
        model_overrides={**SMALL_MODEL, "pretrain_epochs": 1, "pca_variance": 0.95}, **HASH16,
    )  # fmt: skip
    best = train_model(cfg, log=lambda s: None)
    stored = np.asarray(load_checkpoint(best)["model_config"]["pca_components"])  # (K, P)

    features = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 16})
    train, val = split_takes(load_dataset(cfg.data, features, cfg.cache_dir), cfg.val_fraction, cfg.seed)
    assert val  # one take held out ...
    norm = Normalization.fit(train)
    train_poses = np.concatenate([norm.pose(t.poses) for t in train])
    np.testing.assert_array_equal(np.concatenate(seen), train_poses)  # ... and only the training takes fitted
    expected, _ = fit_pose_pca([train_poses], 0.95)
    np.testing.assert_allclose(np.abs(stored), np.abs(expected), atol=1e-5)  # up to each axis's sign
    assert variance_kept(stored, train_poses) >= 0.95

    gen = GesticulatorGenerator(best)
    k, p = stored.shape
    assert k < p and gen.model.output.out_features == k
    torch.testing.assert_close(gen.model.pca_basis, torch.tensor(stored, dtype=torch.float32))
    speech = synthesize("Hello there, I am a robot and I wave.")
    x = gen.inputs(speech)
    assert gen.predict(x).shape == (x.shape[0], p)
    motion = gen.generate(speech)
    assert motion.n_frames == speech.n_frames and np.isfinite(motion.rotations).all()


def test_a_model_wrapped_without_normalisation_says_so():
    from robogest.data import FeatureConfig
    from robogest.errors import InputError
    from robogest.generators.learned.gesticulator import GesticulatorGenerator

    net = GesticulatorNet(GesticulatorConfig(n_acoustic=4, n_text=3, n_pose=6)).eval()
    gen = GesticulatorGenerator.from_model(net, FeatureConfig(text_encoder="hash-test"))
    with pytest.raises(InputError, match=r"no normalisation statistics; pass norm= to GesticulatorGenerator"):
        gen.predict(np.zeros((5, 7), np.float32))
