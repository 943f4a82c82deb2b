"""Baselines share the estimator interface and fit what they should."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.offline.kpls.baselines import KernelRidgeRetarget, LinearPLS, LinearRetarget, PairRBF, PCARBFRetarget

ALL = [PairRBF, LinearRetarget, LinearPLS, KernelRidgeRetarget, PCARBFRetarget]


@pytest.mark.parametrize("cls", ALL)
def test_baselines_fit_a_smooth_map_and_refuse_bad_use(cls):
    rng = np.random.default_rng(0)
    W = rng.uniform(0, 1, size=(120, 4))
    F = rng.normal(size=(4, 9))  # 9 "feature" numbers spanning 4 dimensions, like rig displacements
    X, Y = W @ F, W @ rng.normal(size=(4, 3))
    model = cls().fit(X, Y)
    assert model.fit(X, Y) is model
    Wt = rng.uniform(0.1, 0.9, size=(30, 4))
    Yt_pred = model.predict(Wt @ F)
    assert Yt_pred.shape == (30, 3)
    Yt = Wt @ np.linalg.lstsq(W, Y, rcond=None)[0]
    assert np.sqrt(np.mean((Yt_pred - Yt) ** 2)) < 0.05 * Y.std()
    with pytest.raises(ValueError, match="not fitted yet"):
        cls().predict(X)
    with pytest.raises(ValueError, match="unequal numbers of pairs"):
        cls().fit(X, Y[:-1])
    with pytest.raises(ValueError, match="features, fitted on 9"):
        model.predict(X[:, :5])


def test_dutreve_transfers_displacements_through_the_face_to_face_warp():
    from facepuppet.offline.kpls.dutreve_rbf import DutreveRBF

    rng = np.random.default_rng(1)
    p = rng.normal(size=(20, 3))
    A = np.diag([1.5, 0.7, 1.0]) + 0.1 * rng.normal(size=(3, 3))
    q = p @ A.T + [1.0, -2.0, 0.5]  # the output face is an affine copy of the input face
    model = DutreveRBF(p, q, out_positions=q[:6]).fit()
    d = 0.05 * rng.normal(size=(4, 20, 3))
    # a thin-plate warp with a linear tail reproduces an affine map: displacements go through A
    np.testing.assert_allclose(model.predict(d.reshape(4, -1)), (d[:, :6] @ A.T).reshape(4, -1), atol=1e-8)
    with pytest.raises(ValueError, match="not fitted yet"):
        DutreveRBF(p, q, q).predict(d.reshape(4, -1))
    with pytest.raises(ValueError, match="X has 9 features, fitted on 60"):
        model.predict(np.zeros((1, 9)))
