"""Cotangent Laplacian, lumped mass matrix and the bi-Laplacian of a triangle mesh.

Yano & Harada (2009) deform the skin as a thin elastic plate in pure bending;
discretised on a triangle mesh this is the bi-Laplacian ``K M^-1 K`` with the
cotangent stiffness matrix ``K`` and the lumped (barycentric) mass matrix
``M``. Symbols → code names:

    K (cotangent Laplacian, positive semi-definite)   cotangent_laplacian(...)
    M (lumped vertex areas, diagonal)                  vertex_areas(...) / mass_matrix(...)
    Δ² ≈ K M^-1 K                                      bilaplacian(...)

Degenerate triangles (zero area) contribute nothing; vertices in no triangle
get a tiny mass so ``M`` stays invertible. Several connected components (eyes,
teeth) are allowed; :func:`components` labels them.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

_AREA_EPS = 1e-12


def check_mesh(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices as (n, 3) float64 and triangles as (m, 3) int64, or ValueError saying what came."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"vertices: expected shape (n, 3) with n > 0, got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError("vertices: contain NaN or infinity")
    if t.ndim != 2 or t.shape[1] != 3 or t.dtype.kind not in "iu":
        raise ValueError(f"triangles: expected integer array of shape (m, 3), got {t.dtype} {t.shape}")
    t = t.astype(np.int64)
    if len(t) and (t.min() < 0 or t.max() >= len(v)):
        raise ValueError(f"triangles: indices must lie in 0..{len(v) - 1}, got {t.min()}..{t.max()}")
    return v, t


def _corner_cotangents(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cotangent of the angle at each corner, (m, 3), and twice each triangle's area, (m,)."""
    cots = np.zeros((len(t), 3))
    p = v[t]
    double_area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    ok = double_area > _AREA_EPS
    for c in range(3):
        a = p[:, (c + 1) % 3] - p[:, c]
        b = p[:, (c + 2) % 3] - p[:, c]
        cots[ok, c] = np.einsum("ij,ij->i", a[ok], b[ok]) / double_area[ok]
    return cots, double_area


def cotangent_laplacian(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Cotangent stiffness matrix K (positive semi-definite, rows sum to zero).

    ``K[i, j] = -(cot α_ij + cot β_ij) / 2`` for an edge (i, j) and
    ``K[i, i] = -Σ_j K[i, j]``.

    Parameters
    ----------
    vertices : ndarray of shape (n, 3), float, any length unit
    triangles : ndarray of shape (m, 3), int

    Returns
    -------
    scipy.sparse.csr_matrix of shape (n, n), float64, unitless
    """
    v, t = check_mesh(vertices, triangles)
    cots, _ = _corner_cotangents(v, t)
    rows, cols, vals = [], [], []
    for c in range(3):
        # The angle at corner c faces the edge between the two other corners.
        i, j = t[:, (c + 1) % 3], t[:, (c + 2) % 3]
        w = 0.5 * cots[:, c]
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-w, -w, w, w]
    n = len(v)
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )


def vertex_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric vertex areas (one third of each incident triangle), (n,) float64, units².

    Vertices in no (non-degenerate) triangle get a tiny positive area so that
    the mass matrix stays invertible.
    """
    v, t = check_mesh(vertices, triangles)
    _, double_area = _corner_cotangents(v, t)
    areas = np.zeros(len(v))
    np.add.at(areas, t.reshape(-1), np.repeat(double_area / 6.0, 3))
    floor = max(areas.max(initial=0.0), 1.0) * 1e-12
    return np.maximum(areas, floor)


def mass_matrix(vertices: np.ndarray, triangles: np.ndarray) -> sp.dia_matrix:
    """Lumped mass matrix M = diag(vertex_areas), (n, n) sparse float64."""
    return sp.diags(vertex_areas(vertices, triangles))


def bilaplacian(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Pure-bending operator B = K M^-1 K, (n, n) sparse float64, symmetric positive semi-definite."""
    k = cotangent_laplacian(vertices, triangles)
    inv_m = sp.diags(1.0 / vertex_areas(vertices, triangles))
    return (k @ inv_m @ k).tocsr()


def components(n_vertices: int, triangles: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the mesh edge graph.

    Returns
    -------
    count : int
    labels : ndarray of shape (n_vertices,), int32; isolated vertices form their own component
    """
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    rows = t.reshape(-1)
    cols = np.roll(t, 1, axis=1).reshape(-1)
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    count, labels = connected_components(graph, directed=False)
    return int(count), labels.astype(np.int32)


def vertex_gradients(vertices: np.ndarray, triangles: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """Per-vertex surface gradient operators (Gx, Gy, Gz), each (n, n) sparse float64, 1/units.

    ``G @ f`` is the area-weighted mean over the incident triangles of the
    gradient of the piecewise-linear function with vertex values ``f``.
    """
    v, t = check_mesh(vertices, triangles)
    p = v[t]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    double_area = np.linalg.norm(normal, axis=1)
    ok = double_area > _AREA_EPS
    t, p, normal, double_area = t[ok], p[ok], normal[ok], double_area[ok]
    unit = normal / double_area[:, None]
    # Gradient of the hat function of corner c: (n̂ × opposite edge) / (2A).
    grads = [np.cross(unit, p[:, (c + 2) % 3] - p[:, (c + 1) % 3]) / double_area[:, None] for c in range(3)]
    weight = np.zeros(len(v))
    np.add.at(weight, t.reshape(-1), np.repeat(double_area, 3))
    weight = np.maximum(weight, _AREA_EPS)
    ops = []
    for axis in range(3):
        rows, cols, vals = [], [], []
        for c in range(3):
            g = grads[c][:, axis] * double_area  # area-weighted triangle gradient contribution
            for r in range(3):
                rows.append(t[:, r])
                cols.append(t[:, c])
                vals.append(g / weight[t[:, r]])
        ops.append(
            sp.csr_matrix(
                (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(len(v), len(v))
            )
        )
    return ops[0], ops[1], ops[2]
