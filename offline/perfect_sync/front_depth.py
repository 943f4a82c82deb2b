"""A face's skin seen from the front: its depth buffer in the face frame, and the valleys in it.

The features a coarse fit of control points misses by millimetres (the lid margins, the lip line) are
plain to see from the front: where the eye opens, the skin in front is missing or far behind the lids
above and below it; the lips meet in a crease deeper than the lips on either side. Both are valleys
along the face's up axis, measured here on a depth buffer of the skin (looking along −z of the face
frame), so that no source mesh and no tuned template is needed.
"""

from __future__ import annotations

import numpy as np


def depth_buffer(local: np.ndarray, triangles: np.ndarray, x0: float, y0: float, h: float,
                 shape: tuple[int, int]) -> np.ndarray:
    """(rows, cols) front-most z of ``triangles`` over ``local`` (n, 3) face-frame positions, on pixels of size
    ``h`` whose first centre is (x0, y0); rows run up (y), columns across (x); −inf where nothing is drawn."""
    return front_buffers(local, triangles, x0, y0, h, shape)[0]


def front_buffers(local: np.ndarray, triangles: np.ndarray, x0: float, y0: float, h: float,
                  shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The depth buffer of :func:`depth_buffer` and beside it (rows, cols) the index into ``triangles`` of the
    front-most triangle at each pixel, −1 where none is drawn."""
    rows, cols = shape
    zbuf = np.full(shape, -np.inf)
    ids = np.full(shape, -1, np.int64)
    p = local[triangles]  # (m, 3, 3)
    lo = np.floor((p[:, :, :2].min(1) - (x0, y0)) / h).astype(np.int64)
    hi = np.ceil((p[:, :, :2].max(1) - (x0, y0)) / h).astype(np.int64)
    keep = np.flatnonzero((hi[:, 0] >= 0) & (lo[:, 0] < cols) & (hi[:, 1] >= 0) & (lo[:, 1] < rows))
    for t in keep:
        c0, r0 = max(lo[t, 0], 0), max(lo[t, 1], 0)
        c1, r1 = min(hi[t, 0], cols - 1), min(hi[t, 1], rows - 1)
        if c1 < c0 or r1 < r0:
            continue
        xs, ys = np.meshgrid(x0 + h * np.arange(c0, c1 + 1), y0 + h * np.arange(r0, r1 + 1))
        a, b, c = p[t]
        det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if abs(det) < 1e-18:
            continue
        wb = ((xs - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (ys - a[1])) / det
        wc = ((b[0] - a[0]) * (ys - a[1]) - (xs - a[0]) * (b[1] - a[1])) / det
        wa = 1.0 - wb - wc
        inside = (wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9)
        z = np.where(inside, wa * a[2] + wb * b[2] + wc * c[2], -np.inf)
        view, own = zbuf[r0:r1 + 1, c0:c1 + 1], ids[r0:r1 + 1, c0:c1 + 1]
        nearer = z > view
        view[nearer] = z[nearer]
        own[nearer] = t
    return zbuf, ids


def valley(zbuf: np.ndarray, reach: int) -> np.ndarray:
    """(rows, cols): how far each pixel lies behind the front-most skin both above and below it within
    ``reach`` pixels in its column (the smaller of the two heights; negative on a ridge, about zero on a
    slope, where one side is lower); −inf stays where nothing is drawn."""
    finite = np.where(np.isfinite(zbuf), zbuf, -1e30)
    above, below = np.full(zbuf.shape, -1e30), np.full(zbuf.shape, -1e30)
    for k in range(1, reach + 1):
        np.maximum(above[:-k], finite[k:], out=above[:-k])
        np.maximum(below[k:], finite[:-k], out=below[k:])
    return np.minimum(above, below) - zbuf
