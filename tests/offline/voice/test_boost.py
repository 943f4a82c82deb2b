"""The voice table's boosted trees: they learn what a line cannot, the run time evaluates exactly what the fit
predicted (the blend on the kit's speech: test_fit_voice)."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec
from facepuppet.runtime.voice.trees import TreeEvaluator

from facepuppet.offline.voice.boost import BoostSetting, fit_trees, predict_trees
from facepuppet.offline.voice.fit import Standardise, fit_model, pearson, to_table


def _band_data(n, seed):
    """y is 1 where a feature lies in a middle band (as an open vowel's first formant lies between a closed one's
    and a noise's) : by symmetry no line in the features explains the band."""
    rng = np.random.default_rng(seed)
    Z = rng.standard_normal((n, 6))
    y = (np.abs(Z[:, 0]) < 0.67).astype(float)
    return Z, np.c_[y, 1 - y]


def test_trees_learn_a_band_no_line_can_and_generalise_to_new_rows():
    Z, Y = _band_data(1500, 0)
    Zt, Yt = _band_data(500, 1)
    trees = fit_trees(Z, Y, BoostSetting(n_trees=80, rate=0.2, depth=2))
    P = predict_trees(Zt, *trees)
    W = np.linalg.lstsq(np.c_[Z, np.ones(len(Z))], Y, rcond=None)[0]
    L = np.c_[Zt, np.ones(len(Zt))] @ W
    assert pearson(P[:, 0], Yt[:, 0]) > 0.9
    assert abs(pearson(L[:, 0], Yt[:, 0])) < 0.2
    np.testing.assert_allclose(P[:, 0] + P[:, 1], 1.0, atol=0.05)  # two outputs, each its own trees


def test_a_feature_that_never_varies_is_never_split_on():
    Z, Y = _band_data(600, 2)
    Z[:, 0] = 3.0  # constant: the interaction is gone, no cut exists
    _, feature, threshold, _ = fit_trees(Z, Y, BoostSetting(n_trees=10, depth=2))
    split = threshold < np.finfo(np.float64).max
    assert split.any() and not (feature[split] == 0).any()


def test_the_run_time_evaluator_gives_exactly_the_fits_tree_sums():
    Z, Y = _band_data(800, 3)
    base, feature, threshold, value = fit_trees(Z, Y, BoostSetting(n_trees=30, depth=3))
    P = predict_trees(Z[:100], base, feature, threshold, value)
    ev = TreeEvaluator(feature, threshold, value, 2, Z.shape[1])
    out = np.zeros(2, np.float32)
    for i in range(100):
        out[:] = base
        ev(Z[i].astype(np.float32), out)
        np.testing.assert_allclose(out, P[i], rtol=0, atol=2e-6)


def test_a_blend_table_predicts_what_the_blend_fit_predicts():
    rng = np.random.default_rng(4)
    spec = FeatureSpec(n_mels=6, n_taps=2, step=1)
    X = rng.normal(-40, 10, (400, spec.n_features))
    X[:, -1] = rng.uniform(-30, -5, 400)  # loud: the gate stays open
    Y = np.clip(np.c_[0.5 + 0.4 * np.tanh((X[:, 0] + 40) / 5), 0.2 + 0.3 * (X[:, 1] > -40) * (X[:, 2] > -35)], 0, 1)
    table = to_table("blend", 100.0, X, Y, ("jawOpen", "mouthFunnel"), spec, 0.0, -70.0, {})
    fitted = fit_model("blend", X, Y, 100.0)
    np.testing.assert_allclose(table.predict(X[:60]), np.clip(fitted(X[:60]), 0, 1), atol=2e-5)
    st = Standardise(X)
    ridge = fit_model("ridge", X, Y, 100.0)(X[:60])
    trees = predict_trees(st(X[:60]), *fit_trees(st(X), Y))
    np.testing.assert_allclose(fitted(X[:60]), 0.5 * ridge + 0.5 * trees, atol=1e-9)  # a mean of the two
