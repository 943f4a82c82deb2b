"""Detail transfer by compact-support radial basis functions (Ju & Lee 2008, §5.2).

Detail features measured at marker positions p_i (displacements d_i) are
carried onto a character mesh by the interpolant

    f(x) = Σ_i w_i φ(|x - p_i| / r),   f(p_j) = d_j          (§5.2, no linear term)

with the cubic B-spline kernel of support radius r (φ = 0 beyond r, so each
vertex is moved only by the markers within r of it: the detail stays in its
region). The weights solve the sparse system Φ w = d
(:func:`scipy.sparse.linalg.spsolve`).

Symbols: p_i -> ``centres``, d_i -> ``values``, w_i -> ``weights_``, r -> ``radius``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree


def cubic_bspline(q: np.ndarray) -> np.ndarray:
    """Cubic B-spline of q = distance / radius, support [0, 1), φ(0) = 1 (§5.2 kernel).

    φ(q) = 1 - 6 q² + 6 q³ for q < 1/2, 2 (1 - q)³ for 1/2 <= q < 1, 0 beyond.
    """
    q = np.asarray(q, np.float64)
    return np.where(q < 0.5, 1.0 - 6.0 * q ** 2 + 6.0 * q ** 3, np.where(q < 1.0, 2.0 * (1.0 - q) ** 3, 0.0))


class RBFTransfer:
    """Compact-support RBF interpolant from marker positions to any points (scikit-learn style).

    Parameters
    ----------
    radius : float, support radius r, in the positions' units
    """

    def __init__(self, radius: float) -> None:
        self.radius = radius

    def fit(self, centres: np.ndarray, values: np.ndarray) -> RBFTransfer:
        """centres : (n, 3) float, marker positions; values : (n, k) float, detail features at them."""
        c = np.asarray(centres, np.float64)
        v = np.asarray(values, np.float64)
        if c.ndim != 2 or c.shape[1] != 3 or not np.isfinite(c).all():
            raise ValueError(f"centres: expected finite shape (n, 3), got {c.shape}")
        if v.ndim == 1:
            v = v[:, None]
        if v.shape[0] != c.shape[0] or not np.isfinite(v).all():
            raise ValueError(f"values: expected finite shape ({c.shape[0]}, k), got {v.shape}")
        if not self.radius > 0:
            raise ValueError(f"radius: expected a positive number, got {self.radius}")
        phi = self._matrix(c, c)  # Φ_ji = φ(|p_j - p_i| / r)
        self.weights_ = np.asarray(spsolve(phi.tocsc(), v)).reshape(v.shape)  # §5.2: Φ w = d
        self.centres_ = c
        return self

    def _matrix(self, x: np.ndarray, c: np.ndarray) -> sp.csr_matrix:
        tree = cKDTree(c)
        pairs = tree.query_ball_point(x, self.radius)
        rows = np.repeat(np.arange(len(x)), [len(p) for p in pairs])
        cols = np.concatenate([np.asarray(p, np.int64) for p in pairs]) if len(rows) else np.zeros(0, np.int64)
        q = np.linalg.norm(x[rows] - c[cols], axis=1) / self.radius
        return sp.csr_matrix((cubic_bspline(q), (rows, cols)), shape=(len(x), len(c)))

    def transform(self, points: np.ndarray) -> np.ndarray:
        """f(x) at ``points`` (m, 3): ndarray of shape (m, k), zero where no marker is within r (§5.2)."""
        if not hasattr(self, "weights_"):
            raise ValueError("RBFTransfer: call fit(centres, values) before transform")
        x = np.asarray(points, np.float64)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"points: expected shape (m, 3), got {x.shape}")
        return self._matrix(x, self.centres_) @ self.weights_
