"""Elastic basis functions of Yano & Harada (2009), §3–4, and their compact form.

The skin is a thin plate in pure bending. With the control points (handles)
displaced by u_i and a far region held fixed, the displacement field d that
minimises the bending energy (eq. 3) solves the bi-Laplacian system (eq. 4);
because the system is linear, d is a weighted sum of one basis function per
control point (eq. 5), each precomputed once with a sparse factorisation.

Symbols → code names:

    c_i (control points / handles)          handles, (n_c,) vertex indices
    u_i (control displacement)              rows of U, (n_c, 3)
    b_i(x) (basis function of handle i)     column i of weights_ (n, n_c)
    Ω_fixed (fixed far region, §4)          fixed_mask_ (n,) bool
    r (fixed-region ratio, §4)              fixed_ratio
    k (kept weights per vertex, compact)    k; compact_indices_, compact_weights_ (n, k)

Components of the mesh with no handle (eyes, teeth) and not named free are
held fixed (``detached_mask_``); naming such a component free is an error,
because its bending system would be singular.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from facepuppet.runtime.errors import InputFileError, UsageError

from facepuppet.offline.elastic.laplacian import bilaplacian, check_mesh, components, vertex_gradients

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

DEFAULT_FIXED_RATIO = 1.4
DEFAULT_K = 8


def fixed_region(vertices: np.ndarray, nose_tip: ArrayLike, forehead: ArrayLike,
                 ratio: float = DEFAULT_FIXED_RATIO) -> np.ndarray:
    """Vertices far from the nose tip: |x - nose| > ratio * |forehead - nose| (Yano & Harada §4).

    Parameters
    ----------
    vertices : ndarray of shape (n, 3), float, units
    nose_tip, forehead : array_like of shape (3,), units
    ratio : float > 0

    Returns
    -------
    ndarray of shape (n,), bool
    """
    if not ratio > 0:
        raise UsageError(f"fixed_ratio: expected a positive number, got {ratio!r}")
    v = np.asarray(vertices, dtype=np.float64)
    nose = np.asarray(nose_tip, dtype=np.float64)
    scale = float(np.linalg.norm(np.asarray(forehead, dtype=np.float64) - nose))
    if scale <= 0:
        raise InputFileError("forehead: must differ from the nose tip to set the fixed-region scale")
    return np.linalg.norm(v - nose, axis=1) > ratio * scale  # Yano & Harada §4 distance rule


def check_handles(handles: np.ndarray, n_vertices: int, fixed_mask: np.ndarray,
                  names: Sequence[str] | None = None) -> np.ndarray:
    """Handles as (n_c,) int64, or ValueError on duplicates, range or a handle in the fixed region."""
    h = np.asarray(handles)
    if h.ndim != 1 or len(h) == 0 or h.dtype.kind not in "iu":
        raise InputFileError(f"handles: expected a non-empty 1-D array of vertex indices, got {h.dtype} {h.shape}")
    h = h.astype(np.int64)
    label = (lambda i: f"{names[i]!r} (vertex {h[i]})") if names is not None else (lambda i: f"vertex {h[i]}")
    if h.min() < 0 or h.max() >= n_vertices:
        raise ValueError(f"handles: vertex indices must lie in 0..{n_vertices - 1}, got {h.min()}..{h.max()}")
    uniq, first, counts = np.unique(h, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = uniq[counts > 1][0]
        which = [label(i) for i in np.flatnonzero(h == dup)]
        raise InputFileError(f"handles: duplicate handles on one vertex: {', '.join(which)}")
    inside = np.flatnonzero(fixed_mask[h])
    if len(inside):
        raise InputFileError(
            f"handles: control point {label(inside[0])} lies in the fixed region; "
            "raise the fixed-region ratio or move the control point"
        )
    return h


class ElasticBasis:
    """Basis functions of the pure-bending deformation for one mesh and one set of handles.

    Parameters
    ----------
    k : int, weights kept per vertex in the compact form (default 8)
    free_components : sequence of int
        Handle-free components the caller insists must deform; an error (their
        bending system has no constraint). Default: none, they are held fixed.

    Attributes (after fit)
    ----------------------
    weights_ : ndarray of shape (n, n_c), float64, the full basis b_i(x_v) (eq. 5)
    fixed_mask_, detached_mask_ : ndarray of shape (n,), bool
    compact_indices_ : ndarray of shape (n, k), uint16, control indices, largest |weight| first
    compact_weights_ : ndarray of shape (n, k), float32
    compact_gradients_ : ndarray of shape (n, k, 3), float32, surface gradient of each kept b_i, 1/units
    solve_seconds_ : float, factorisation plus solve time
    """

    def __init__(self, k: int = DEFAULT_K, free_components: Sequence[int] = ()) -> None:
        self.k = int(k)
        self.free_components = tuple(int(c) for c in free_components)

    def fit(self, vertices: np.ndarray, triangles: np.ndarray, handles: np.ndarray,
            fixed_mask: np.ndarray | None = None, names: Sequence[str] | None = None) -> ElasticBasis:
        """Precompute the basis (eqs. 3–5) and its compact form.

        Parameters
        ----------
        vertices : ndarray of shape (n, 3), float, units
        triangles : ndarray of shape (m, 3), int
        handles : ndarray of shape (n_c,), int, control-point vertices
        fixed_mask : ndarray of shape (n,), bool, or None for no fixed region
        names : sequence of n_c str or None, used in error messages
        """
        v, t = check_mesh(vertices, triangles)
        n = len(v)
        fixed = np.zeros(n, bool) if fixed_mask is None else np.asarray(fixed_mask, bool).copy()
        if fixed.shape != (n,):
            raise ValueError(f"fixed_mask: expected shape ({n},), got {fixed.shape}")
        h = check_handles(handles, n, fixed, names)
        if not 1 <= self.k:
            raise UsageError(f"k: expected a positive number of kept weights, got {self.k}")
        count, labels = components(n, t)
        with_handle = np.zeros(count, bool)
        with_handle[labels[h]] = True
        for c in self.free_components:
            if not 0 <= c < count:
                raise ValueError(f"free_components: component {c} does not exist (mesh has {count})")
            if not with_handle[c]:
                raise ValueError(
                    f"free_components: component {c} ({int((labels == c).sum())} vertices) is disconnected "
                    "from every control point and has no handle, so its bending system is singular; "
                    "add a control point on it or leave it fixed"
                )
        detached = ~with_handle[labels] & ~fixed
        start = time.perf_counter()
        constrained = fixed | detached
        constrained[h] = True
        free = np.flatnonzero(~constrained)
        b = bilaplacian(v, t)  # Yano & Harada eq. 4: K M^-1 K d = 0 on the free vertices
        b_ff = b[free][:, free].tocsc()
        b_fh = b[free][:, h]
        weights = np.zeros((n, len(h)))
        weights[h, np.arange(len(h))] = 1.0  # b_i(c_j) = δ_ij
        if len(free):
            lu = splu(b_ff, permc_spec="COLAMD")
            weights[free] = lu.solve(-b_fh.toarray())  # Yano & Harada eq. 5: one basis function per handle
        self.solve_seconds_ = time.perf_counter() - start
        self.weights_ = weights
        self.handles_ = h
        self.fixed_mask_ = fixed
        self.detached_mask_ = detached
        self.n_components_ = count
        self._compact(v, t)
        return self

    def _compact(self, v: np.ndarray, t: np.ndarray) -> None:
        """Keep the k largest |b_i| per vertex, rescaled so each row keeps its sum."""
        w = self.weights_
        k = min(self.k, w.shape[1])
        order = np.argsort(-np.abs(w), axis=1, kind="stable")[:, :k]
        kept = np.take_along_axis(w, order, axis=1)
        full_sum, kept_sum = w.sum(axis=1), kept.sum(axis=1)
        ok = np.abs(kept_sum) > 1e-9
        scale = np.ones(len(w))
        scale[ok] = full_sum[ok] / kept_sum[ok]
        gx, gy, gz = vertex_gradients(v, t)
        grads = np.stack([np.take_along_axis(g @ w, order, axis=1) for g in (gx, gy, gz)], axis=-1)
        if k < self.k:  # fewer controls than k: pad with zero weights on control 0
            pad = self.k - k
            order = np.pad(order, ((0, 0), (0, pad)))
            kept = np.pad(kept, ((0, 0), (0, pad)))
            grads = np.pad(grads, ((0, 0), (0, pad), (0, 0)))
        self.compact_indices_ = order.astype(np.uint16)
        self.compact_weights_ = (kept * scale[:, None]).astype(np.float32)
        self.compact_gradients_ = (grads * scale[:, None, None]).astype(np.float32)

    def compact_matrix(self) -> sp.csr_matrix:
        """The compact basis as a sparse (n, n_c) float64 matrix."""
        n, k = self.compact_weights_.shape
        rows = np.repeat(np.arange(n), k)
        return sp.csr_matrix(
            (self.compact_weights_.reshape(-1).astype(np.float64), (rows, self.compact_indices_.reshape(-1))),
            shape=(n, len(self.handles_)),
        )

    def displace(self, controls: np.ndarray, compact: bool = False) -> np.ndarray:
        """Vertex displacements for control displacements U: d = Σ_i b_i u_i (eq. 5), (n, 3) float64."""
        u = np.asarray(controls, dtype=np.float64)
        if u.shape != (len(self.handles_), 3):
            raise ValueError(f"controls: expected shape ({len(self.handles_)}, 3), got {u.shape}")
        w = self.compact_matrix() if compact else self.weights_
        return np.asarray(w @ u)  # Yano & Harada eq. 5
