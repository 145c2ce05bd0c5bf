"""Fréchet distance, window features, diversity and lexeme entropy against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.eval.features import (
    diversity,
    feature_distances,
    frechet_distance,
    geometric_features,
    kinetic_features,
    lexeme_entropy,
    sliding_windows,
)


def test_identical_sets_have_zero_distance(rng):
    x = rng.normal(size=(200, 6))
    assert frechet_distance(x, x.copy()) == pytest.approx(0.0, abs=1e-6)


def test_shifted_set_gives_the_mean_difference_term(rng):
    x = rng.normal(size=(300, 5)) @ rng.normal(size=(5, 5))
    c = np.array([1.0, -2.0, 0.5, 0.0, 3.0])
    assert frechet_distance(x, x + c) == pytest.approx(float(c @ c), rel=1e-6)


def test_scaled_set_gives_the_covariance_term(rng):
    x = rng.normal(size=(400, 1))
    s2 = float(np.var(x, ddof=1))
    # Σ_a = s², Σ_b = 4 s², (Σ_a Σ_b)^½ = 2 s²  →  tr = s² + 4 s² - 4 s² = s²
    assert frechet_distance(x - x.mean(), 2 * (x - x.mean())) == pytest.approx(s2, rel=1e-6)


def test_rank_deficient_covariances_stay_finite(rng):
    x = rng.normal(size=(3, 50))  # fewer samples than features
    y = rng.normal(size=(4, 50))
    fd = frechet_distance(x, y)
    assert np.isfinite(fd) and fd > 0


def test_frechet_needs_two_rows():
    with pytest.raises(InputError):
        frechet_distance(np.zeros((1, 3)), np.zeros((5, 3)))


def test_kinetic_features_of_constant_velocity():
    fps = 30.0
    t = np.arange(31) / fps
    w = np.zeros((31, 1, 3))
    w[:, 0, 0] = 0.3 * t  # horizontal 0.3 m/s
    w[:, 0, 1] = 0.4 * t  # vertical 0.4 m/s
    ke_h, ke_v, ee = kinetic_features(w, fps)
    assert ke_h == pytest.approx(0.5 * 0.09) and ke_v == pytest.approx(0.5 * 0.16) and ee == pytest.approx(0.0)


def test_geometric_features_are_pairwise_distances():
    w = np.zeros((4, 3, 3))
    w[:, 1, 0] = 3.0
    w[:, 2, 1] = 4.0
    f = geometric_features(w)
    assert f[:3].tolist() == pytest.approx([3.0, 4.0, 5.0]) and np.allclose(f[3:], 0)


def test_feature_distances_same_motion_zero_different_motion_positive(rng):
    fps = 30.0
    t = np.arange(300) / fps
    base = rng.normal(size=(1, 4, 3)) * 0.2
    a = base + 0.1 * np.sin(2 * np.pi * 1.3 * t)[:, None, None] * rng.normal(size=(1, 4, 3))
    a = a + 0.01 * rng.normal(size=a.shape)
    same = feature_distances(a, a.copy(), fps)
    assert same["fd_kinetic"] == pytest.approx(0.0, abs=1e-5) and same["fd_geometric"] == pytest.approx(0, abs=1e-5)
    fast = base + 0.1 * np.sin(2 * np.pi * 3.0 * t)[:, None, None] * rng.normal(size=(1, 4, 3))
    diff = feature_distances(fast, a, fps)
    assert diff["fd_kinetic"] > 1.0 and diff["fd_geometric"] > 1.0
    assert same["n_windows_pred"] == len(sliding_windows(a, fps))


def test_diversity_of_two_points_is_their_distance():
    assert diversity(np.array([[0.0, 0.0], [3.0, 4.0]])) == pytest.approx(5.0)
    assert diversity(np.ones((5, 3))) == 0.0
    assert np.isnan(diversity(np.ones((1, 3))))


def test_lexeme_entropy():
    uniform = lexeme_entropy(np.array([0, 1, 2, 3] * 5), n_lexemes=4)
    assert uniform["entropy_nats"] == pytest.approx(np.log(4)) and uniform["normalized"] == pytest.approx(1.0)
    assert lexeme_entropy(np.zeros(10, int), 4)["entropy_nats"] == 0.0
    skew = lexeme_entropy(np.array([0, 0, 0, 1]))
    assert skew["entropy_nats"] == pytest.approx(-(0.75 * np.log(0.75) + 0.25 * np.log(0.25)))


def test_motion_shorter_than_a_window_gives_nan_distances():
    """Half of a short take (the noise floor) has no window: NaN, not a crash."""
    pos = np.zeros((40, 3, 3))
    out = feature_distances(pos, np.zeros((100, 3, 3)), 30.0)
    assert np.isnan(out["fd_kinetic"]) and np.isnan(out["fd_geometric"]) and out["n_windows_pred"] == 0
