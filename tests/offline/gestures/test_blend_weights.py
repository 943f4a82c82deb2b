"""Bounded blend weights (Ju & Lee §4.1): both solvers recover known weights and keep the bounds."""

import numpy as np
import pytest

from facepuppet.offline.gestures.blend_weights import BlendWeights, temporal_window


@pytest.fixture(scope="module")
def synthetic():
    rng = np.random.default_rng(0)
    basis = rng.normal(size=(4, 30))
    c = rng.uniform(0.0, 1.0, size=(200, 4))
    c[0] = [1.0, 0.0, 0.0, 0.0]  # corners of the box too
    return basis, c, c @ basis


def test_lsq_recovers_known_weights_exactly(synthetic):
    basis, c, X = synthetic
    fit = BlendWeights(basis, epsilon=0.05, window=1, method="lsq").fit(X)
    np.testing.assert_allclose(fit.weights_, c, atol=1e-8)
    assert fit.error_ < 1e-8


def test_knn_recovers_known_weights_approximately(synthetic):
    basis, c, X = synthetic
    fit = BlendWeights(basis, epsilon=0.05, window=1, method="knn", n_samples=20000, n_neighbours=8).fit(X)
    assert np.abs(fit.weights_ - c).mean() < 0.1


@pytest.mark.parametrize("method", ["lsq", "knn"])
def test_weights_respect_the_bounds_on_out_of_range_frames(synthetic, method):
    basis, c, X = synthetic
    eps = 0.1
    fit = BlendWeights(basis, epsilon=eps, window=1, method=method).fit(3.0 * X - 1.0)
    assert fit.weights_.min() >= -eps - 1e-12 and fit.weights_.max() <= 1.0 + eps + 1e-12
    np.testing.assert_allclose(fit.blend_ + fit.residual_, 3.0 * X - 1.0, atol=1e-9)


def test_temporal_window_is_a_centred_moving_average():
    x = np.zeros((9, 1))
    x[4] = 9.0
    np.testing.assert_allclose(temporal_window(x, 3)[:, 0], [0, 0, 0, 3, 3, 3, 0, 0, 0])


def test_bad_inputs_are_refused(synthetic):
    basis, _, X = synthetic
    with pytest.raises(ValueError, match="columns"):
        BlendWeights(basis).fit(X[:, :5])
    bad = X.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        BlendWeights(basis).fit(bad)
