"""Baseline retargeting regressors behind the :class:`~facepuppet.offline.kpls.model.KernelPLS` interface.

Each maps source expressions X (n, n_features), here feature-point
displacements, to target expressions Y (n, n_outputs) (target feature-point
displacements or blendshape weights), learnt from paired examples;
``fit(X, Y)`` returns self, learned state ends in ``_``, ``predict`` refuses
to run unfitted. The spatial method of Dutreve et al. learns nothing from the
pairs (only from the two neutral faces); it lives in :mod:`.dutreve_rbf`.

===========================  ===================================================
class                        method
===========================  ===================================================
:class:`PairRBF`             scattered-data RBF interpolation over the training
                             pairs in expression space (an exact thin-plate
                             spline network through the pairs; not Dutreve's
                             spatial warp, see :mod:`.dutreve_rbf`)
:class:`LinearRetarget`      ordinary least squares (minimum-norm), the linear
                             baseline
:class:`LinearPLS`           linear PLS (scikit-learn ``PLSRegression``)
:class:`KernelRidgeRetarget` kernel ridge regression, RBF kernel
:class:`PCARBFRetarget`      PCA of the source space, then RBF regression from
                             the PCA coefficients to blendshape weights (Deng
                             et al., cross-mapping to blendshape weights)
===========================  ===================================================
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

import numpy as np

from facepuppet.offline.kpls.model import check_inputs, check_pairs

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

_R = TypeVar("_R", bound="_Regressor")  # fit returns the estimator itself, of its own class


class _Regressor:
    """Shared door checks: pairs at fit, fitted state and feature count at predict."""

    def fit(self: _R, X: ArrayLike, Y: ArrayLike) -> _R:
        X, Y = check_pairs(X, Y, f"{type(self).__name__}.fit")
        self.n_features_in_ = X.shape[1]
        self._fit(X, Y)
        return self

    def predict(self, X: ArrayLike) -> np.ndarray:
        """Outputs of shape (n, n_outputs), float64."""
        name = type(self).__name__
        if not hasattr(self, "n_features_in_"):
            raise ValueError(f"{name}.predict: this model is not fitted yet; call fit(X, Y) first")
        X = check_inputs(X, f"{name}.predict: X")
        if X.shape[1] != self.n_features_in_:
            raise ValueError(f"{name}.predict: X has {X.shape[1]} features, fitted on {self.n_features_in_}")
        return self._predict(X)


class PairRBF(_Regressor):
    """RBF network through the training pairs in expression space (x ↦ y interpolated exactly).

    Parameters
    ----------
    kernel : str, a ``scipy.interpolate.RBFInterpolator`` kernel (default thin-plate spline)
    smoothing : float, 0 interpolates the pairs exactly
    """

    def __init__(self, kernel: str = "thin_plate_spline", smoothing: float = 1e-8) -> None:
        self.kernel = kernel
        self.smoothing = smoothing

    def _fit(self, X, Y):
        from scipy.interpolate import RBFInterpolator

        # Feature displacements of a rig span fewer dimensions than 3 k: interpolate in their
        # span (an exact change of coordinates, nothing dropped) so the linear tail is solvable.
        self.x_mean_ = X.mean(0)
        _, sv, vt = np.linalg.svd(X - self.x_mean_, full_matrices=False)
        self.basis_ = vt[sv > sv[0] * 1e-9].T
        self.rbf_ = RBFInterpolator((X - self.x_mean_) @ self.basis_, Y, kernel=self.kernel,
                                    smoothing=self.smoothing, degree=1)

    def _predict(self, X):
        return self.rbf_((X - self.x_mean_) @ self.basis_)


class LinearRetarget(_Regressor):
    """Minimum-norm least squares Y ≈ X A + b (linear regression)."""

    def _fit(self, X, Y):
        self.x_mean_, self.y_mean_ = X.mean(0), Y.mean(0)
        self.coef_ = np.linalg.lstsq(X - self.x_mean_, Y - self.y_mean_, rcond=None)[0]

    def _predict(self, X):
        return (X - self.x_mean_) @ self.coef_ + self.y_mean_


class LinearPLS(_Regressor):
    """Linear PLS with ``n_components`` latent components (scikit-learn ``PLSRegression``, unscaled)."""

    def __init__(self, n_components: int = 20) -> None:
        self.n_components = n_components

    def _fit(self, X, Y):
        from sklearn.cross_decomposition import PLSRegression

        p = min(self.n_components, X.shape[1], len(X) - 1)
        self.pls_ = PLSRegression(n_components=p, scale=False, max_iter=2000).fit(X, Y)

    def _predict(self, X):
        return self.pls_.predict(X).reshape(len(X), -1)


class KernelRidgeRetarget(_Regressor):
    """Kernel ridge regression with an RBF kernel (scikit-learn ``KernelRidge``), centred outputs.

    Parameters
    ----------
    alpha : float, ridge strength
    gamma : float or None; None gives 1 / median squared distance of the training inputs
    """

    def __init__(self, alpha: float = 1e-3, gamma: float | None = None) -> None:
        self.alpha = alpha
        self.gamma = gamma

    def _fit(self, X, Y):
        from sklearn.kernel_ridge import KernelRidge

        gamma = self.gamma
        if gamma is None:
            d = ((X[:, None, :] - X[None, :, :]) ** 2).sum(-1)
            gamma = 1.0 / max(float(np.median(d[np.triu_indices(len(X), 1)])), 1e-12)
        self.gamma_ = gamma
        self.y_mean_ = Y.mean(0)
        self.kr_ = KernelRidge(alpha=self.alpha, kernel="rbf", gamma=gamma).fit(X, Y - self.y_mean_)

    def _predict(self, X):
        return self.kr_.predict(X).reshape(len(X), -1) + self.y_mean_


class PCARBFRetarget(_Regressor):
    """PCA of the source expressions, then RBF regression to blendshape weights (Deng et al.).

    Parameters
    ----------
    n_components : int or float; int: PCA dimensions; float in (0, 1): variance kept
    kernel : str, ``RBFInterpolator`` kernel on the PCA coefficients
    smoothing : float, RBF smoothing
    """

    def __init__(self, n_components: int | float = 0.999, kernel: str = "thin_plate_spline",
                 smoothing: float = 1e-6) -> None:
        self.n_components = n_components
        self.kernel = kernel
        self.smoothing = smoothing

    def _fit(self, X, Y):
        from scipy.interpolate import RBFInterpolator
        from sklearn.decomposition import PCA

        self.pca_ = PCA(n_components=self.n_components, svd_solver="full").fit(X)
        self.rbf_ = RBFInterpolator(self.pca_.transform(X), Y, kernel=self.kernel,
                                    smoothing=self.smoothing, degree=1)

    def _predict(self, X):
        return self.rbf_(self.pca_.transform(X))
