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
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.triangles import skin_front_depth


def keep_clearance(dense: np.ndarray, vertices: np.ndarray, face: Face, moved: np.ndarray,
                   skin_triangles: np.ndarray) -> int:
    """Raise, in place, the displacements ``dense`` (n_shapes, n_vertices, 3) of the ``moved`` vertices where they
    would bring a vertex nearer the still skin (``skin_triangles``) than it lies at rest (see the module doc);
    returns how many (shape, vertex) displacements were raised."""
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
    return raised
