"""Rigid parts of the elastic model: handle-free mesh pieces that follow a rigid transform of control points.

The elastic skin model of Yano & Harada (2009) moves only the surface
connected to control points; separate pieces with no control point (teeth,
gums, tongue, eyeballs) would stay put. Where the paper's model allows it,
such a piece follows rigidly: the lower teeth, gums and tongue follow the
jaw, whose rigid transform is fitted per frame (Kabsch) to the displacements
of the chin, the chin-side jaw points and the lower-lip middle. Everything else stays in place: the upper
teeth with the skull and the eyeballs in their sockets (an eye-look rotation
is outside the elastic skin model: no control point turns an eyeball).

Which handle-free vertices belong to the jaw:

* with example shapes (a character's blendshapes and their eq. 6
  parameters): a vertex joins the jaw when, summed over the shapes, the jaw
  transform fitted to the shape's control displacements explains its motion
  better than staying fixed does;
* without (a bare cloned mesh): when it lies below the inner-lip midline (a
  whole piece by its centre, when the pieces are given).

Symbols → code names: R_s, t_s (jaw rotation and translation of shape s,
fitted to the anchors' control displacements) ``kabsch(rest + U_s[a], rest)``;
a (anchor controls) ``JAW_ANCHORS``.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.rigid import kabsch

from facepuppet.offline.elastic.control_points import ControlPoints

# Measured on ICT jawOpen (RMS error of the rigid vertices, cm; 3.14 if held fixed): chin + jaw_chin_L/R
# + lip_lower 0.48; adding jaw_L/R (the cheek-side contour, which lags the bone) 1.14; without lip_lower 1.79.
JAW_ANCHORS = ("chin", "jaw_chin_L", "jaw_chin_R", "lip_lower")


def jaw_anchor_mask(points: ControlPoints) -> np.ndarray | None:
    """(n_c,) uint8 marking the jaw anchors, or None when the set lacks one of ``JAW_ANCHORS``."""
    if not all(name in points.names for name in JAW_ANCHORS):
        return None
    mask = np.zeros(len(points.names), np.uint8)
    mask[[points.index(name) for name in JAW_ANCHORS]] = 1
    return mask


def jaw_transforms(params: np.ndarray, control_positions: np.ndarray,
                   anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jaw rotation (n_s, 3, 3) and translation (n_s, 3) of each parameter set, fitted to the anchors (Kabsch)."""
    a = np.asarray(anchors, bool)
    rest = np.asarray(control_positions, np.float64)[a]
    u = np.asarray(params, np.float64).reshape(-1, len(a), 3)[:, a]
    return kabsch(rest[None] + u, np.broadcast_to(rest, u.shape))


def rigid_labels(
    vertices: np.ndarray,
    points: ControlPoints,
    detached_mask: np.ndarray,
    params: np.ndarray | None = None,
    deltas: np.ndarray | None = None,
    pieces: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The rigid-part sections of an elastic table: one part, the jaw.

    Parameters
    ----------
    vertices : ndarray of shape (n, 3), float, units
    points : ControlPoints of the mesh (needs ``JAW_ANCHORS``, ``lip_upper_inner``, ``lip_lower_inner``)
    detached_mask : ndarray of shape (n,), bool, handle-free vertices (ElasticBasis.detached_mask_)
    params : ndarray of shape (n_shapes, n_c, 3), float, or None; eq. 6 parameters of ``deltas``
    deltas : ndarray of shape (n_shapes, n, 3), float, units, or None
    pieces : ndarray of shape (n,), int, or None; connected-piece label of each vertex. Without example
        shapes a whole piece joins the jaw when its centre lies below the inner-lip midline (else each
        vertex by its own height, which splits an upper tooth reaching below the midline)

    Returns
    -------
    labels : ndarray of shape (n,), int32, part index or -1 (elastic or fixed)
    anchors : ndarray of shape (n_parts, n_c), uint8, 1 for the controls a part's transform is fitted to
    """
    v = np.asarray(vertices, np.float64)
    detached = np.asarray(detached_mask, bool)
    labels = np.full(len(v), -1, np.int32)
    mask = jaw_anchor_mask(points)
    if mask is None or not detached.any():
        return labels, np.zeros((0, len(points.names)), np.uint8)
    idx = np.flatnonzero(detached)
    if params is not None and deltas is not None and len(params):
        r, t = jaw_transforms(params, v[points.vertices], mask)
        x = v[idx]
        moved = np.einsum("sij,nj->sni", r, x) + t[:, None, :] - x  # jaw motion of each vertex in each shape
        d = np.asarray(deltas, np.float64)[:, idx]
        jaw_residual = ((moved - d) ** 2).sum(axis=(0, 2))
        fixed_residual = (d**2).sum(axis=(0, 2))
        joins = jaw_residual < fixed_residual
    else:
        midline = 0.5 * (v[points.vertex("lip_upper_inner"), 1] + v[points.vertex("lip_lower_inner"), 1])
        if pieces is None:
            joins = v[idx, 1] < midline
        else:
            piece = np.asarray(pieces)[idx]
            _, inverse = np.unique(piece, return_inverse=True)
            centre_y = np.bincount(inverse, weights=v[idx, 1]) / np.bincount(inverse)
            joins = centre_y[inverse] < midline
    labels[idx[joins]] = 0
    return labels, mask[None, :]
