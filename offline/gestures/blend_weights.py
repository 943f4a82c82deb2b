"""Bounded blend weights of a small basis of whole-face expressions (Ju & Lee 2008, §4.1).

Each captured frame x(t) (markers flattened, or dense weights) is expressed as
a blend of ``k`` whole-face expressions B: x(t) ≈ c(t)·B with every weight in
-ε <= c_i <= 1 + ε, after a temporal window (a centred moving average of
``window`` frames, 41 by default) so that c(t) follows the slow mood and the
fast gestures stay in the residual x(t) - c(t)·B.

Two solvers:

* ``"knn"`` (the paper's): ``n_samples`` random weight vectors drawn
  uniformly from the box [-ε, 1+ε]^k, their expressions indexed in a kd-tree
  (:class:`scipy.spatial.cKDTree`); c(t) is the inverse-distance-weighted mean
  of the weights of the ``n_neighbours`` nearest samples. A convex
  combination of in-box samples, so the bounds hold by construction.
* ``"lsq"``: exact bounded least squares per frame
  (:func:`scipy.optimize.lsq_linear`, method "bvls").

Symbols: x(t) -> ``X[t]``, B -> ``basis``, c(t) -> ``weights_[t]``, ε -> ``epsilon``.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.optimize import lsq_linear
from scipy.spatial import cKDTree


def _check_matrix(name: str, a, ndim: int = 2) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-d array, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: expected finite values, found NaN or infinity")
    return a


def temporal_window(X: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average over ``window`` frames (edges repeat), shape as ``X``."""
    if window <= 1:
        return X
    return uniform_filter1d(X, size=int(window), axis=0, mode="nearest")


class BlendWeights:
    """Fit bounded blend weights c(t) of a basis B to frames X (scikit-learn style).

    Parameters
    ----------
    basis : ndarray of shape (k, d), float, the whole-face expressions B
    epsilon : float, slack ε of the bounds -ε <= c <= 1 + ε
    window : int, frames of the temporal window (1: none)
    method : "lsq" or "knn"
    n_samples, n_neighbours : int, the kd-tree method's sample count and k
    seed : int, seed of the random samples
    """

    def __init__(self, basis: np.ndarray, epsilon: float = 0.1, window: int = 41, method: str = "lsq",
                 n_samples: int = 1000, n_neighbours: int = 60, seed: int = 0) -> None:
        self.basis, self.epsilon, self.window, self.method = basis, epsilon, window, method
        self.n_samples, self.n_neighbours, self.seed = n_samples, n_neighbours, seed

    def fit(self, X: np.ndarray) -> BlendWeights:
        """Compute ``weights_`` (n_frames, k), ``blend_`` (n_frames, d) = c·B and ``residual_`` = X - blend_."""
        X = _check_matrix("X", X)
        B = _check_matrix("basis", self.basis)
        if X.shape[1] != B.shape[1]:
            raise ValueError(f"X: expected {B.shape[1]} columns (as the basis), got {X.shape[1]}")
        if self.method not in ("lsq", "knn"):
            raise ValueError(f"method: expected 'lsq' or 'knn', got {self.method!r}")
        lo, hi = -self.epsilon, 1.0 + self.epsilon
        Xw = temporal_window(X, self.window)  # §4.1: temporal window before the fit
        if self.method == "lsq":
            C = np.stack([lsq_linear(B.T, x, bounds=(lo, hi), method="bvls").x for x in Xw])
        else:
            rng = np.random.default_rng(self.seed)
            samples = rng.uniform(lo, hi, size=(self.n_samples, B.shape[0]))  # §4.1: samples of the box
            tree = cKDTree(samples @ B)
            k = min(self.n_neighbours, self.n_samples)
            dist, idx = tree.query(Xw, k=k)
            dist, idx = dist.reshape(len(Xw), k), idx.reshape(len(Xw), k)
            w = 1.0 / np.maximum(dist, 1e-12)  # §4.1: inverse-distance weights
            C = np.einsum("tk,tkj->tj", w, samples[idx]) / w.sum(1, keepdims=True)
        self.weights_ = np.clip(C, lo, hi)
        self.blend_ = self.weights_ @ B                    # §4.1: x(t) ≈ c(t)·B
        self.residual_ = X - self.blend_                    # §4.2: what the regions carry
        self.error_ = float(np.sqrt(np.mean((Xw - self.blend_) ** 2)))
        return self


def choose_basis(X: np.ndarray, k: int = 6, window: int = 41, seed: int = 0) -> np.ndarray:
    """A basis of ``k`` whole-face expressions from data: k-means centres of the windowed frames.

    The first row is the frame-wise minimum (a neutral), so a blend can stay near rest.
    Returns ndarray of shape (k, d), float64.
    """
    from sklearn.cluster import KMeans

    X = _check_matrix("X", X)
    Xw = temporal_window(X, window)
    km = KMeans(n_clusters=max(1, k - 1), n_init=4, random_state=seed).fit(Xw)
    return np.vstack([np.percentile(Xw, 5, axis=0), km.cluster_centers_])
