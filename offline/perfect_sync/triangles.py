"""Points against triangles: the closest point on a triangle, the nearest triangle, the frontmost surface.

The geometry the face's pieces need (:mod:`.pieces`, :mod:`.on_skin`,
:mod:`.drawn_eyes`) and the mouth's clearance (:mod:`.transfer`): where a
piece's vertex lies on the skin, how far it is from it, and what surface is in
front of it along the line of sight.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray,
                                                                                                np.ndarray]:
    """Closest points of triangles (a, b, c) (m, 3) to points ``p`` (m, 3): (points (m, 3), barycentric (m, 3)).

    Ericson, Real-Time Collision Detection §5.1.5 (Voronoi regions of the vertices, edges and face).
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    denom = np.where(np.abs(denom) < 1e-30, 1e-30, denom)
    v, w = vb / denom, vc / denom  # inside the face
    bary = np.stack([1 - v - w, v, w], 1)

    def put(mask, u):
        bary[mask] = u[mask]

    safe = lambda x: np.where(np.abs(x) < 1e-30, 1e-30, x)  # noqa: E731
    # edges (checked before the vertices, which override them)
    t = d1 / safe(d1 - d3)
    put((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([1 - t, t, 0 * t], 1))
    t = d2 / safe(d2 - d6)
    put((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([1 - t, 0 * t, t], 1))
    t = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), np.stack([0 * t, 1 - t, t], 1))
    one = np.ones(len(p))
    zero = np.zeros(len(p))
    put((d1 <= 0) & (d2 <= 0), np.stack([one, zero, zero], 1))
    put((d3 >= 0) & (d4 <= d3), np.stack([zero, one, zero], 1))
    put((d6 >= 0) & (d5 <= d6), np.stack([zero, zero, one], 1))
    q = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return q, bary


def nearest_triangles(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                      k: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point its nearest triangle among the ``k`` with the nearest centroids: (triangle index (n,),
    barycentric (n, 3), distance (n,))."""
    p = np.asarray(points, np.float64)
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    k = min(k, len(t))
    _, cand = cKDTree(v[t].mean(1)).query(p, k=k)
    cand = np.asarray(cand).reshape(len(p), k)
    best_d = np.full(len(p), np.inf)
    best_t = np.zeros(len(p), np.int64)
    best_b = np.zeros((len(p), 3))
    for j in range(k):
        tri = t[cand[:, j]]
        q, bary = closest_on_triangles(p, v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]])
        d = np.linalg.norm(p - q, axis=1)
        better = d < best_d
        best_d[better], best_t[better], best_b[better] = d[better], cand[better, j], bary[better]
    return best_t, best_b, best_d


def skin_front_depth(xy: np.ndarray, local: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Depth (face-frame z) of the frontmost surface of ``triangles`` on the line of sight (along the face's
    forward) through each of the points ``xy`` (m, 2), NaN where none crosses it; ``local`` the vertices in the
    face frame."""
    out = np.full(len(xy), -np.inf)
    if len(xy) and len(triangles):  # only the triangles whose front-view box meets the points' box can cross them
        box = local[np.asarray(triangles)][:, :, :2]
        lo, hi = np.nanmin(xy, axis=0), np.nanmax(xy, axis=0)
        triangles = np.asarray(triangles)[((box.max(axis=1) >= lo) & (box.min(axis=1) <= hi)).all(axis=1)]
    for start in range(0, len(triangles), 4096):
        t = local[triangles[start:start + 4096]]  # (k, 3, 3)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        ok = np.abs(det) > 1e-18
        a, b, c, det = a[ok], b[ok], c[ok], det[ok]
        px, py = xy[:, None, 0] - a[None, :, 0], xy[:, None, 1] - a[None, :, 1]
        u = (px * (c[:, 1] - a[:, 1]) - py * (c[:, 0] - a[:, 0])) / det
        w = (py * (b[:, 0] - a[:, 0]) - px * (b[:, 1] - a[:, 1])) / det
        hit = (u >= -1e-9) & (w >= -1e-9) & (u + w <= 1 + 1e-9)
        z = a[None, :, 2] + u * (b[:, 2] - a[:, 2]) + w * (c[:, 2] - a[:, 2])
        out = np.maximum(out, np.where(hit, z, -np.inf).max(axis=1, initial=-np.inf))
    return np.where(np.isfinite(out), out, np.nan)
