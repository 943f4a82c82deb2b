"""Feature-point retargeting by RBF warps in space (Dutreve, Meyer, Bouakaz 2008), the paper's main baseline.

Dutreve et al. learn nothing from example expressions. Two RBF networks in
3-D space do the transfer:

1. a warp φ: R³ → R³ between the two *neutral* faces, fitted so that each
   input feature point p_i lands on its counterpart q_i on the output face;
   a displaced input point p_i + d_i goes to φ(p_i + d_i), so the output
   displacement there is e_i = φ(p_i + d_i) − q_i;
2. a deformation of the output face: the displacements e_i at the q_i are
   interpolated over the output face by an RBF in space (skinning the mesh
   to the feature points), read at the output's feature points or vertices.

Step 2 is linear in e, so it is one precomputed matrix G (n_out, k_in).
When the output is a blendshape rig, its weights are the least-squares fit
of the deformed vertices (``out_basis``), one more precomputed matrix.

Symbols and names: p ``in_points``; q ``in_on_out``; φ ``warp_``; output
positions ``out_positions``; G ``spread_``.

Counterparts q of the input points on the output face are needed (Dutreve et
al. place them by hand): :func:`corresponding_vertices` uses the vertex itself
when both faces share a topology, else the nearest free output vertex once both
faces' moving regions are scaled into the same bounding box (distinct, as RBF
centres must be).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import RBFInterpolator

from facepuppet.runtime.model.character import Character

from facepuppet.offline.kpls.model import check_inputs
from facepuppet.offline.kpls.pairs import moving_region

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def corresponding_vertices(a: Character, b: Character, idx_a: np.ndarray) -> np.ndarray:
    """Vertices of character ``b`` (k,) int64 matching vertices ``idx_a`` of character ``a``."""
    idx_a = np.asarray(idx_a, dtype=np.int64)
    if a.n_vertices == b.n_vertices and np.array_equal(a.triangles, b.triangles):
        return idx_a
    ra, rb = moving_region(a), moving_region(b)
    pa, pb = a.vertices[ra].astype(np.float64), b.vertices[rb].astype(np.float64)
    lo_a, span_a = pa.min(0), np.ptp(pa, axis=0)
    lo_b, span_b = pb.min(0), np.ptp(pb, axis=0)
    moved = (a.vertices[idx_a] - lo_a) / np.where(span_a > 0, span_a, 1.0) * span_b + lo_b
    dist = ((moved[:, None, :] - pb[None, :, :]) ** 2).sum(-1)
    chosen = np.empty(len(idx_a), dtype=np.int64)
    taken = np.zeros(len(pb), dtype=bool)
    for i in np.argsort(dist.min(axis=1)):  # nearest free vertex: RBF centres must be distinct
        j = int(np.argmin(np.where(taken, np.inf, dist[i])))
        chosen[i], taken[j] = j, True
    return rb[chosen]


class DutreveRBF:
    """Spatial feature-point transfer (Dutreve et al.): RBF warp between faces, then RBF deformation.

    Parameters
    ----------
    in_points : ndarray of shape (k_in, 3), input face's feature points at neutral, input units
    in_on_out : ndarray of shape (k_in, 3), their counterparts on the output face, output units
    out_positions : ndarray of shape (n_out, 3), output-face points whose displacement is wanted
    out_basis : ndarray of shape (3 n_out, n_weights) or None; given, predict returns the
        least-squares weights w with out_basis @ w ≈ displacements (a blendshape rig's fit)
    kernel : str, ``scipy.interpolate.RBFInterpolator`` kernel of both RBF networks
    """

    def __init__(self, in_points: np.ndarray, in_on_out: np.ndarray, out_positions: np.ndarray,
                 out_basis: np.ndarray | None = None, kernel: str = "thin_plate_spline") -> None:
        self.in_points = in_points
        self.in_on_out = in_on_out
        self.out_positions = out_positions
        self.out_basis = out_basis
        self.kernel = kernel

    def fit(self, X: ArrayLike | None = None, Y: ArrayLike | None = None) -> DutreveRBF:
        """Build both RBF networks from the neutral faces; example pairs X, Y are checked, not learnt from."""
        p = check_inputs(self.in_points, "DutreveRBF: in_points")
        q = check_inputs(self.in_on_out, "DutreveRBF: in_on_out")
        out = check_inputs(self.out_positions, "DutreveRBF: out_positions")
        if p.shape != q.shape or p.shape[1] != 3:
            raise ValueError(f"DutreveRBF: in_points {p.shape} and in_on_out {q.shape} must both be (k, 3)")
        if X is not None and np.shape(X)[1] != p.size:
            raise ValueError(f"DutreveRBF.fit: X has {np.shape(X)[1]} features, {len(p)} points need {p.size}")
        self.k_in_ = len(p)
        self.warp_ = RBFInterpolator(p, q, kernel=self.kernel, degree=1)  # face-to-face warp φ
        self.spread_ = RBFInterpolator(q, np.eye(len(q)), kernel=self.kernel, degree=1)(out)  # G
        self.p_, self.q_ = p, q
        if self.out_basis is not None:
            basis = np.asarray(self.out_basis, dtype=np.float64)
            if basis.shape[0] != out.size:
                raise ValueError(f"DutreveRBF: out_basis has {basis.shape[0]} rows, {len(out)} output "
                                 f"positions need {out.size}")
            # weights = B⁺ (G ⊗ I₃) e, folded into one (n_weights, k_in, 3) tensor
            pinv = np.linalg.pinv(basis).reshape(basis.shape[1], len(out), 3)
            self.to_weights_ = np.einsum("wrc,rk->wkc", pinv, self.spread_)
        return self

    def predict(self, X: ArrayLike) -> np.ndarray:
        """Output displacements (n, 3 n_out) or weights (n, n_weights) for input displacements X (n, 3 k_in)."""
        if not hasattr(self, "warp_"):
            raise ValueError("DutreveRBF.predict: this model is not fitted yet; call fit() first")
        X = check_inputs(X, "DutreveRBF.predict: X")
        if X.shape[1] != 3 * self.k_in_:
            raise ValueError(f"DutreveRBF.predict: X has {X.shape[1]} features, fitted on {3 * self.k_in_}")
        d = X.reshape(len(X), self.k_in_, 3)
        moved = self.warp_((self.p_[None] + d).reshape(-1, 3)).reshape(d.shape)
        e = moved - self.q_[None]  # displacement at the counterparts: φ(p + d) − q
        if self.out_basis is not None:
            return np.einsum("wkc,nkc->nw", self.to_weights_, e)
        return np.einsum("rk,nkc->nrc", self.spread_, e).reshape(len(X), -1)
