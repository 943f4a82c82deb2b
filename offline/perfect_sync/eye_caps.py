"""The thin pieces lying on an eyeball slide over it as the lids carry them; they never lift off through the lid.

An eye is often more than its ball: ICT's has a tear film, a shadow mesh and a caruncle lying on the sclera, up
to 0.26 cm in front of its sphere. They lie on the skin's edge at the opening, so they are carried by the skin
like lashes (:mod:`.on_skin`): each vertex takes its nearest skin triangle's displacement, a translation. A lid
coming down over a ball moves along its curve; translated straight down with it, a cap's vertex leaves the ball's
surface, and where the lid passes close over it the cap comes through: dark pinholes above the closed lid's line
(:mod:`.lid_cover`).

A cap is a piece that is not skin, not the ball, in front of the ball's centre and whose every vertex lies
within :data:`CAP` of the ball's largest radius from its centre. After the pieces are carried
(:func:`~.transfer.carry_pieces`), each cap vertex is put back at its rest distance from the eye's centre, along
the direction the carrying took it: it slides over the ball as the lid moves it, never through the lid.
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.elastic.laplacian import components

CAP = 0.2  # a cap's vertices lie within this fraction of the ball's largest radius from it (ICT's: 0.1)


def eye_caps(vertices: np.ndarray, triangles: np.ndarray, eyes: dict, forward: np.ndarray) -> dict:
    """{"L"/"R": vertex indices of the caps lying on that eyeball} (``eyes``: side -> (ball vertices, centre), as
    :func:`~.transfer.eyeballs` gives; ``forward`` the face's front direction)."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    _, labels = components(len(v), t)
    balls = np.concatenate([m for m, _ in eyes.values()] + [np.zeros(0, np.int64)])
    taken = set(np.unique(labels[balls]).tolist())
    out: dict = {}
    for side, (members, centre) in eyes.items():
        radius = float(np.linalg.norm(v[members] - centre, axis=1).max())
        found = []
        for lab in np.unique(labels[np.unique(t)]):
            if lab in taken:
                continue
            piece = np.flatnonzero(labels == lab)
            rel = v[piece] - centre
            dist = np.linalg.norm(rel, axis=1)
            if np.abs(dist - radius).max() <= CAP * radius and rel.mean(0) @ forward > 0:
                found.append(piece)
        if found:
            out[side] = np.concatenate(found)
    return out


def keep_on_ball(dense: np.ndarray, vertices: np.ndarray, eyes: dict, caps: dict) -> int:
    """Put, in place, each cap vertex of ``caps[side]`` in ``dense`` (n_shapes, n_vertices, 3) back at its rest
    distance from its eye's centre along its shaped direction (see the module doc); returns how many (shape,
    vertex) displacements it changed by more than a thousandth of the ball's radius."""
    v = np.asarray(vertices, np.float64)
    changed = 0
    for side, cap in caps.items():
        members, centre = eyes[side]
        radius = float(np.linalg.norm(v[members] - centre, axis=1).max())
        rest = np.linalg.norm(v[cap] - centre, axis=1)
        for s in range(dense.shape[0]):
            q = v[cap] + dense[s, cap]
            rel = q - centre
            put = centre + rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-12) * rest[:, None]
            changed += int((np.linalg.norm(put - q, axis=1) > 1e-3 * radius).sum())
            dense[s, cap] = (put - v[cap]).astype(dense.dtype)
    return changed
