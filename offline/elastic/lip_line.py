"""Inner-lip correspondences on a target whose mouth is closed (cloning, Yano & Harada 2009 §5).

Nearest-point proposals fail at a closed mouth: the upper and lower inner-lip
points of the source land on one line on the target, often in the wrong
order, and jawOpen then pulls the lips through each other. This module fixes
the inner-lip control points after the proposal:

* if the target mesh has a lip line, the upper and lower inner lips as
  separate vertex paths from corner to corner: either a boundary loop between
  the lips (split at its leftmost and rightmost vertices) or given (the
  MediaPipe canonical face, whose lip line is bridged by a strip of
  triangles: :func:`cut_lip_line` removes that strip so that the lips can
  part); ``mouth_inner_L/R``
  take the slit's corners, ``lip_upper_inner`` the upper-lip vertex and
  ``lip_lower_inner`` the lower-lip vertex nearest the proposed ones in x;
* otherwise (no slit) the upper point is taken among the candidates above the
  proposed pair's midline and the lower one below it, so that their order
  (upper above lower) holds.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from facepuppet.offline.elastic.control_points import ControlPoints

UPPER, LOWER = "lip_upper_inner", "lip_lower_inner"
CORNERS = ("mouth_inner_R", "mouth_inner_L")
# The inner lip line of the MediaPipe face mesh (468 vertices), right corner to left corner.
MEDIAPIPE_INNER_LIPS = (
    (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308),
    (78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308),
)


def cut_lip_line(triangles: np.ndarray, upper: Iterable[int], lower: Iterable[int]) -> np.ndarray:
    """``triangles`` without the strip bridging the upper and lower inner lip paths, (m', 3) same dtype.

    A bridging triangle has all three corners on the lip line and touches both lips.
    """
    t = np.asarray(triangles)
    up, low = set(int(i) for i in upper), set(int(i) for i in lower)
    on_line = np.isin(t, list(up | low)).all(axis=1)
    touches_up = np.isin(t, list(up - low)).any(axis=1)
    touches_low = np.isin(t, list(low - up)).any(axis=1)
    return t[~(on_line & touches_up & touches_low)]


def boundary_loops(n_vertices: int, triangles: np.ndarray) -> list:
    """Vertex loops of the mesh boundary (edges in one triangle), each an ordered (p,) int64 array."""
    t = np.asarray(triangles, np.int64)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    border = unique[counts == 1]
    if not len(border):
        return []
    graph = sp.coo_matrix((np.ones(len(border)), (border[:, 0], border[:, 1])), shape=(n_vertices, n_vertices)).tocsr()
    graph = graph + graph.T
    _, labels = connected_components(graph, directed=False)
    loops = []
    for label in np.unique(labels[border[:, 0]]):
        members = np.flatnonzero(labels == label)
        if (np.diff(graph.indptr)[members] != 2).any():
            continue  # not a simple loop
        order, previous = [members[0]], -1
        while True:
            nxt = [int(j) for j in graph.indices[graph.indptr[order[-1]]:graph.indptr[order[-1] + 1]] if j != previous]
            previous = order[-1]
            if nxt[0] == order[0]:
                break
            order.append(nxt[0])
        loops.append(np.array(order, np.int64))
    return loops


def mouth_slit(vertices: np.ndarray, triangles: np.ndarray, near: np.ndarray,
               max_width: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(upper, lower) vertex paths of the boundary loop nearest ``near`` and narrower than ``max_width``, or None."""
    v = np.asarray(vertices, np.float64)
    best, best_d = None, np.inf
    for loop in boundary_loops(len(v), triangles):
        width = np.ptp(v[loop, 0])
        d = np.linalg.norm(v[loop] - near, axis=1).min()
        if len(loop) >= 6 and width < max_width and d < best_d:
            best, best_d = loop, d
    if best is None or best_d > 0.5 * max_width:
        return None
    i, j = sorted((int(np.argmin(v[best, 0])), int(np.argmax(v[best, 0]))))
    one, two = best[i:j + 1], np.concatenate([best[j:], best[:i + 1]])
    return (one, two) if v[one, 1].mean() > v[two, 1].mean() else (two, one)


def fix_inner_lips(points: ControlPoints, vertices: np.ndarray, triangles: np.ndarray, candidates: np.ndarray,
                   slit: tuple[np.ndarray, np.ndarray] | None = None) -> ControlPoints:
    """``points`` with the inner-lip points in order on a closed mouth (see the module docstring).

    Parameters
    ----------
    points : ControlPoints proposed on the target
    vertices : ndarray of shape (n, 3), float, target units
    triangles : ndarray of shape (m, 3), int
    candidates : ndarray of int, vertices allowed as control points
    slit : (upper, lower) vertex paths from the right to the left mouth corner, or None to look for a
        boundary loop between the lips
    """
    if UPPER not in points.names or LOWER not in points.names:
        return points
    v = np.asarray(vertices, np.float64)
    verts = points.vertices.copy()
    up, low = points.index(UPPER), points.index(LOWER)
    mid = 0.5 * (v[verts[up]] + v[verts[low]])
    corners = [points.index(n) for n in ("mouth_corner_R", "mouth_corner_L") if n in points.names]
    width = np.ptp(v[verts[corners], 0]) if len(corners) == 2 else np.inf
    if slit is None:
        slit = mouth_slit(v, triangles, mid, 1.5 * width)
    else:
        slit = tuple(np.asarray(path, np.int64) for path in slit)
    others = set(int(x) for i, x in enumerate(verts) if i not in (up, low) and points.names[i] not in CORNERS)
    if slit is not None:
        upper, lower = slit
        pick = lambda path, x: int(path[np.argmin(np.abs(v[path, 0] - x))])  # noqa: E731
        verts[up], verts[low] = pick(upper[1:-1], v[verts[up], 0]), pick(lower[1:-1], v[verts[low], 0])
        ends = sorted((upper[0], upper[-1]), key=lambda i: v[i, 0])  # right (x < 0) first
        for name, vertex in zip(CORNERS, ends):
            if name in points.names and int(vertex) not in others:
                verts[points.index(name)] = vertex
    elif v[verts[up], 1] <= v[verts[low], 1]:
        cand = np.array([c for c in np.asarray(candidates, np.int64) if int(c) not in others])
        d = np.linalg.norm(v[cand] - mid, axis=1)
        above, below = cand[v[cand, 1] > mid[1]], cand[v[cand, 1] < mid[1]]
        if len(above) and len(below):
            verts[up] = above[np.argmin(d[v[cand, 1] > mid[1]])]
            verts[low] = below[np.argmin(d[v[cand, 1] < mid[1]])]
    return ControlPoints(points.names, verts)
