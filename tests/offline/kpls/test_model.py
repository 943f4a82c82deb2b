"""Kernel PLS (Ouzounis et al.): non-linear recovery, linear-kernel equivalence, deflation, input checks."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.cross_decomposition import PLSRegression

from facepuppet.offline.kpls.model import KernelPLS, centre_gram, kernel_matrix, nipals


def _nonlinear(n, seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(n, 3))
    Y = np.stack([np.sin(2.5 * X[:, 0]) + X[:, 1] ** 2, X[:, 0] * X[:, 2] + np.cos(2 * X[:, 1])], 1)
    return X, Y


def test_rbf_kpls_recovers_a_nonlinear_map_better_than_linear_pls():
    X, Y = _nonlinear(160, 0)
    Xt, Yt = _nonlinear(200, 1)
    kpls = KernelPLS(kernel="rbf").fit(X, Y)
    mse_k = np.mean((kpls.predict(Xt) - Yt) ** 2)
    mse_l = np.mean((PLSRegression(n_components=3, scale=False).fit(X, Y).predict(Xt) - Yt) ** 2)
    assert mse_k < 0.1 * mse_l, (mse_k, mse_l)
    assert mse_k < 0.01 * np.var(Yt)
    assert kpls.n_components_ in kpls.cv_errors_
    assert kpls.cv_errors_[kpls.n_components_] == min(kpls.cv_errors_.values())
    # every count scored is one all folds support: finite scores only, from 1 up without gaps
    assert all(np.isfinite(v) for v in kpls.cv_errors_.values())
    assert sorted(kpls.cv_errors_) == list(range(1, max(kpls.cv_errors_) + 1))


def test_cv_running_sum_matches_a_refit_per_count():
    X, Y = _nonlinear(60, 8)
    m = KernelPLS(kernel="rbf", gamma=0.5, max_components=12, cv_folds=3).fit(X, Y)
    folds = np.array_split(np.random.default_rng(0).permutation(60), 3)
    for p in (1, 5, 12):
        sse = 0.0
        for test in folds:
            train = np.setdiff1d(np.arange(60), test)
            ref = KernelPLS(n_components=p, kernel="rbf", gamma=0.5).fit(X[train], Y[train])
            sse += ((ref.predict(X[test]) - Y[test]) ** 2).sum()
        assert m.cv_errors_[p] == pytest.approx(sse / Y.size, rel=1e-8)


def test_eigh_solver_is_the_fixed_point_of_the_nipals_iteration():
    X, Y = _nonlinear(50, 9)
    Kc, _, _ = centre_gram(kernel_matrix(X, X, "rbf", 1.0, 0, 0))
    T1, U1 = nipals(Kc, Y - Y.mean(0), 4, solver="eigh")
    T2, U2 = nipals(Kc, Y - Y.mean(0), 4, tol=1e-14, max_iter=100000, solver="power")
    np.testing.assert_allclose(np.abs(T1.T @ T2), np.eye(4), atol=1e-6)
    # an exhausted Gram matrix stops the components instead of returning noise
    Xl = np.random.default_rng(1).normal(size=(30, 2))
    Kl, _, _ = centre_gram(kernel_matrix(Xl, Xl, "linear", 0, 0, 0))
    assert nipals(Kl, Xl @ np.ones((2, 3)), 10)[0].shape == (30, 2)
    with pytest.raises(ValueError, match="exhausted after 2 of the 5 components"):
        KernelPLS(5, kernel="linear").fit(Xl, Xl @ np.ones((2, 3)))


@pytest.mark.parametrize("p", [1, 2, 4, 6])
def test_linear_kernel_matches_ordinary_pls(p):
    rng = np.random.default_rng(3)
    X = rng.normal(size=(50, 6)) @ rng.normal(size=(6, 6))
    Y = X @ rng.normal(size=(6, 3)) + 0.2 * rng.normal(size=(50, 3))
    Xt = rng.normal(size=(20, 6))
    ours = KernelPLS(n_components=p, kernel="linear", tol=1e-13, max_iter=20000).fit(X, Y)
    ref = PLSRegression(n_components=p, scale=False, tol=1e-14, max_iter=20000).fit(X, Y)
    np.testing.assert_allclose(ours.predict(Xt), ref.predict(Xt), rtol=1e-6, atol=1e-6)
    # the X scores span the same space as ordinary PLS's
    t_ref = ref.x_scores_ / np.linalg.norm(ref.x_scores_, axis=0)
    np.testing.assert_allclose(np.abs(ours.x_scores_.T @ t_ref), np.eye(p), atol=1e-6)


def test_gram_deflation_gives_orthonormal_scores():
    X, Y = _nonlinear(60, 4)
    Kc, _, _ = centre_gram(kernel_matrix(X, X, "rbf", 1.0, 0, 0))
    T, U = nipals(Kc, Y - Y.mean(0), 8)
    np.testing.assert_allclose(T.T @ T, np.eye(8), atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(U, axis=0), 1.0)


def test_kernels_match_a_loop_reference():
    rng = np.random.default_rng(5)
    A, B = rng.normal(size=(4, 3)), rng.normal(size=(5, 3))
    for kernel, f in [("rbf", lambda a, b: np.exp(-0.7 * ((a - b) ** 2).sum())),
                      ("poly", lambda a, b: (0.7 * a @ b + 1.5) ** 3),
                      ("linear", lambda a, b: a @ b)]:
        ref = np.array([[f(a, b) for b in B] for a in A])
        np.testing.assert_allclose(kernel_matrix(A, B, kernel, 0.7, 1.5, 3), ref, rtol=1e-12)


def test_test_kernel_is_centred_like_the_training_gram():
    X, Y = _nonlinear(40, 6)
    m = KernelPLS(n_components=3, kernel="poly").fit(X, Y)
    Kc, _, _ = centre_gram(kernel_matrix(X, X, "poly", m.gamma_, m.coef0, m.degree))
    np.testing.assert_allclose(m.centred_kernel(X), Kc, atol=1e-10)


def test_bad_inputs_get_clear_errors():
    X, Y = _nonlinear(20, 7)
    with pytest.raises(ValueError, match="unequal numbers of pairs: X has 20 rows, Y has 19"):
        KernelPLS(2).fit(X, Y[:19])
    Xn = X.copy()
    Xn[3, 1] = np.nan
    with pytest.raises(ValueError, match="X contains NaN"):
        KernelPLS(2).fit(Xn, Y)
    with pytest.raises(ValueError, match="single pair"):
        KernelPLS(1).fit(X[:1], Y[:1])
    with pytest.raises(ValueError, match="too many components: n_components=20 but 20 pairs allow at most 19"):
        KernelPLS(20).fit(X, Y)
    with pytest.raises(ValueError, match="kernel must be one of"):
        KernelPLS(2, kernel="sigmoid").fit(X, Y)
    with pytest.raises(ValueError, match="not fitted yet"):
        KernelPLS(2).predict(X)
    with pytest.raises(ValueError, match="X has 2 features, the model was fitted on 3"):
        KernelPLS(2).fit(X, Y).predict(X[:, :2])


def test_cross_validation_skips_counts_a_fold_cannot_support_instead_of_scoring_them_inf():
    # a linear kernel on inputs spanning 6 dimensions: every fold's Gram matrix is exhausted after 6
    # components, long before the n - fold - 1 counts the fold sizes would allow
    rng = np.random.default_rng(3)
    W = rng.uniform(0, 1, size=(80, 6))
    X = W @ rng.normal(size=(6, 20))
    m = KernelPLS(kernel="linear").fit(X, W)
    assert max(m.cv_errors_) == 6 and all(np.isfinite(v) for v in m.cv_errors_.values())
    np.testing.assert_allclose(m.predict(X), W, atol=1e-8)


def test_auto_kernel_picks_the_linear_kernel_for_a_linear_map_and_rbf_for_a_curved_one():
    rng = np.random.default_rng(4)
    W = rng.uniform(0, 1, size=(120, 5))
    X = W @ rng.normal(size=(5, 12))
    m = KernelPLS(kernel="auto").fit(X, W)
    assert m.kernel_ == "linear" and set(m.cv_scores_) >= {"linear", "poly", "rbf x1"}
    assert m.cv_scores_["linear"] == min(m.cv_scores_.values())
    Xn, Yn = _nonlinear(160, 0)
    assert KernelPLS(kernel="auto").fit(Xn, Yn).kernel_ != "linear"
    notes = []
    KernelPLS(kernel="auto", cv_folds=3).fit(X, W, progress=notes.append)
    assert len(notes) == 3 * (2 + len(KernelPLS().gamma_scales))  # one note per fold per candidate
