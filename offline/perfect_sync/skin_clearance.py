"""Drawn pieces kept in front of a still skin: a decal face's features slide over the skin, never into it.

On a decal face (Godette's box head) the skin stays still and its drawn pieces (the eyes, the mouth, the
brows and lashes lying on the skin) move by the landmark field of the source's control points. That field
carries the source's depth motion too: a brow that rises moves back along the source's round forehead, a
smile's mouth corners back along its cheeks. The decal's skin is flatter than the source's, or bulges where
the source's does not, so a piece moved that way goes behind the skin it lies on, and the viewer sees a
brow or a lip line torn or gone.

A drawn piece lies a small height in front of the skin (its depth minus the skin's front-most depth on its
line of sight, both in the face frame). Each moved vertex keeps at least that height in front of the skin
at the place the field moves it to (seen from the front): where the field would take it closer to the
skin or behind it, its depth is raised to the skin's there plus its rest height; its motion across the face
is left as it is. Vertices with no skin behind them at rest or after the move (past the face's edge) are left
as they are.

Keeping the vertices clear is not enough: a piece's triangles are flat and the skin under them need not be.
Where a piece slides over a convex crease of the skin (Godette's brows, raised over the corner of her box
head), the crease comes through the middle of a triangle whose corners are all clear, and the viewer sees a
notch of skin across the brow, its outer end apart like a hook (:mod:`.poke_through` measures it). So each
moved triangle of the pieces (``triangles``) is sampled on a grid about ``SPACING`` face widths apart, each
sample keeps its own rest height over the skin at its new place like a vertex, and a triangle whose sample
falls short is lifted, all three corners by its largest shortfall (lifting the corners lifts every point of
the triangle by at least as much; a corner shared by several triangles takes the largest lift of them).
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.poke_through import grid
from facepuppet.offline.perfect_sync.triangles import skin_front_depth

SPACING = 0.005  # face widths between the samples of a piece's triangle (Godette's brow: about 0.05 inner-eye
# distances; at most MAX_STEPS a side)
MAX_STEPS = 16


def keep_clearance(dense: np.ndarray, vertices: np.ndarray, face: Face, moved: np.ndarray,
                   skin_triangles: np.ndarray, triangles: np.ndarray = ()) -> int:
    """Raise, in place, the displacements ``dense`` (n_shapes, n_vertices, 3) of the ``moved`` vertices where they
    would bring a vertex, or a point of one of the pieces' ``triangles`` (t, 3), nearer the still skin
    (``skin_triangles``) than it lies at rest (see the module doc); returns how many (shape, vertex)
    displacements were raised."""
    moved = np.unique(np.asarray(moved, np.int64))
    if not len(moved) or not len(skin_triangles):
        return 0
    local = face.to_frame(np.asarray(vertices, np.float64))
    rest = local[moved]
    height = rest[:, 2] - skin_front_depth(rest[:, :2], local, skin_triangles)
    ok = np.isfinite(height)
    moved, rest, height = moved[ok], rest[ok], np.maximum(height[ok], 0.0)
    raised = 0
    for s in range(dense.shape[0]):
        d = dense[s, moved].astype(np.float64) @ face.frame.T  # the displacement in the face frame
        go = np.flatnonzero(np.abs(d).max(axis=1) > 0)
        if not len(go):
            continue
        new = rest[go] + d[go]
        floor = skin_front_depth(new[:, :2], local, skin_triangles) + height[go]
        low = np.isfinite(floor) & (new[:, 2] < floor)
        if not low.any():
            continue
        d[go[low], 2] += floor[low] - new[low, 2]
        dense[s, moved[go[low]]] = (d[go[low]] @ face.frame).astype(dense.dtype)
        raised += int(low.sum())
    if len(triangles):
        raised += _keep_triangles_clear(dense, local, face, np.asarray(triangles, np.int64), skin_triangles)
    return raised


def _keep_triangles_clear(dense: np.ndarray, local: np.ndarray, face: Face, triangles: np.ndarray,
                          skin_triangles: np.ndarray) -> int:
    """The triangles' part of :func:`keep_clearance` (see the module doc), ``local`` the rest vertices in the face
    frame; returns how many (shape, vertex) displacements were raised."""
    edge = np.linalg.norm(local[triangles] - local[np.roll(triangles, 1, axis=1)], axis=2).max(axis=1)
    steps = np.clip(np.ceil(edge / max(SPACING * face.width, 1e-12)), 1, MAX_STEPS).astype(np.int64)
    groups = []  # (its triangles, barycentrics, rest height of each sample (t, k))
    for n in np.unique(steps):
        t = triangles[steps == n]
        bary = grid(int(n))
        rest = np.einsum("sk,tkc->tsc", bary, local[t])
        height = rest[..., 2] - skin_front_depth(rest[..., :2].reshape(-1, 2), local,
                                                 skin_triangles).reshape(len(t), len(bary))
        height = np.where(np.isfinite(height), np.maximum(height, 0.0), np.nan)  # no skin behind at rest: not kept
        groups.append((t, bary, height))
    raised = 0
    for s in range(dense.shape[0]):
        lift = np.zeros(len(local))
        d = dense[s].astype(np.float64) @ face.frame.T
        for t, bary, height in groups:
            go = np.abs(d[t]).max(axis=(1, 2)) > 0
            if not go.any():
                continue
            new = np.einsum("sk,tkc->tsc", bary, local[t[go]] + d[t[go]])
            floor = skin_front_depth(new[..., :2].reshape(-1, 2), local,
                                     skin_triangles).reshape(new.shape[:2]) + height[go]
            short = np.nan_to_num(floor - new[..., 2], nan=0.0, neginf=0.0).max(axis=1)
            for k in range(3):
                np.maximum.at(lift, t[go][:, k], short)
        if face.weld is not None:  # a seam's copies are lifted with their first copy, which the triangles hold
            lift = np.maximum(lift, lift[face.weld])
        up = np.flatnonzero(lift > 0)
        if len(up):
            d[up, 2] += lift[up]
            dense[s, up] = (d[up] @ face.frame).astype(dense.dtype)
            raised += len(up)
    return raised
