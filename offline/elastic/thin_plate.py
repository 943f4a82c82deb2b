"""A 3-D thin-plate spline: a smooth map of space through given point pairs.

The biharmonic kernel of 3-D space, φ(r) = r, on each source point plus an
affine part: of the maps taking the points (nearly) where they are asked to
go, the one that bends space least. With a smoothing term the map need not
pass through each pair exactly, so a few pairs placed a little off do not
crease it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.distance import cdist


def thin_plate(src: np.ndarray, dst: np.ndarray, smoothing: float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
    """The 3-D thin-plate spline W with W(src) ≈ dst: φ(r) = r kernels on ``src`` plus an affine part."""
    p = np.asarray(src, np.float64)
    n = len(p)
    # φ = r is conditionally negative definite: its smoothing term enters with the opposite sign
    k = np.linalg.norm(p[:, None] - p[None], axis=2) - smoothing * np.eye(n)
    poly = np.column_stack([np.ones(n), p])
    a = np.block([[k, poly], [poly.T, np.zeros((4, 4))]])
    rhs = np.vstack([np.asarray(dst, np.float64), np.zeros((4, 3))])
    coef = np.linalg.solve(a, rhs)
    w, affine = coef[:n], coef[n:]

    def warp(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, np.float64)
        out = np.column_stack([np.ones(len(x)), x]) @ affine
        for start in range(0, len(x), 65536):  # (chunk, n) distances at a time
            out[start:start + 65536] += cdist(x[start:start + 65536], p) @ w
        return out

    return warp
