"""Where a closed mouth's lips touch, and the mouth's inner corners put on that contact.

The inner corners of the mouth (MPEG-4 2.4/2.5, the ends of the inner lip line) are not on the skin seen
from the front: they lie under the upper lip, on the lower lip's skin that faces up against the upper
lip's skin facing down. On a head whose mouth is shaped otherwise than the source's (lips fuller or
tucked further in at the corners) the corner lies deeper behind the front-most skin, and the coarse fit,
which keeps to forward-facing skin, takes a vertex on the outer lip beside it instead; the cloning then
gives that vertex the inner corner's motion (rolls, presses, funnels) and the outer lip's, two points a
hair apart with different motions.

The contact is a plain geometric fact: the skin vertices facing up (normal's up component > ``FACING``)
that have a vertex facing down within ``TOUCH`` inner-eye distances (ES), near the mouth. Each inner
corner takes the contact vertex nearest, in the front view, to the place it was given (the lip line's
end, :mod:`.mouth_slit`), when one lies within ``REACH``; otherwise, and on a mouth whose lips do not
touch (an open mouth, a slit: :func:`~facepuppet.offline.elastic.lip_line.fix_inner_lips` puts the
corners at the slit's ends), it keeps its place and says so (:func:`corner_doubts`).

Set on the source, the ICT head: its inner corners face up (0.92) and touch the upper lip's skin within
0.002 ES; TOUCH leaves room for a warp that stretches the lips' gap. Checked on the real-proportion
variants of ``bench perfect-sync`` (:mod:`.real_variants`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.perfect_sync.face import Face

logger = logging.getLogger(__name__)

INNER_CORNERS = ("mouth_inner_R", "mouth_inner_L")
FACING = 0.3  # a lip's contact skin faces up (lower lip) or down (upper lip) at least this much
TOUCH = 0.05  # ... with the other lip's skin within this many ES
REACH = 0.15  # an inner corner moves to a contact vertex within this many ES of its place (front view)
NEAR_MOUTH = (1.2, 0.3)  # the contact is looked for within this many ES across / up and down of the mouth


def lip_contact(vertices: np.ndarray, face: Face, triangles: np.ndarray, centre: np.ndarray,
                es: float) -> np.ndarray:
    """The lower lip's skin vertices touching the upper lip's (int64; see the module doc) near the mouth whose
    centre (world) is ``centre``; ``triangles`` the skin's, for the normals."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    normals = vertex_normals(np.asarray(vertices, np.float32), np.asarray(triangles, np.uint32))
    up = normals.astype(np.float64)[face.skin] @ face.frame[1]
    c = face.to_frame(np.asarray(centre, np.float64))
    near = (np.abs(local[face.skin, 0] - c[0]) < NEAR_MOUTH[0] * es) & (
        np.abs(local[face.skin, 1] - c[1]) < NEAR_MOUTH[1] * es)
    lower, upper = face.skin[near & (up > FACING)], face.skin[near & (up < -FACING)]
    if not len(lower) or not len(upper):
        return np.zeros(0, np.int64)
    d, _ = cKDTree(local[upper]).query(local[lower])
    return lower[d < TOUCH * es].astype(np.int64)


def inner_corners(names: Sequence[str], chosen: Sequence[int], vertices: np.ndarray, face: Face,
                  triangles: np.ndarray) -> tuple[list, list]:
    """(``chosen`` with each inner corner on the lips' contact, the names of the corners left where they were
    because no contact lies within ``REACH`` of them); ``chosen`` the vertex per name of ``names``."""
    names = tuple(names)
    out = [int(c) for c in chosen]
    if not all(n in names for n in (*INNER_CORNERS, "eye_inner_L", "eye_inner_R")):
        return out, []
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    es = float(np.linalg.norm(local[out[names.index("eye_inner_L")], :2] - local[out[names.index("eye_inner_R")],
                                                                                 :2]))
    if es <= 0:
        return out, list(INNER_CORNERS)
    ends = [out[names.index(n)] for n in INNER_CORNERS]
    contact = lip_contact(v, face, triangles, v[ends].mean(0), es)
    taken = set(out)
    missed = []
    for name in INNER_CORNERS:
        i = names.index(name)
        free = np.array([c for c in contact if int(c) not in taken or int(c) == out[i]], np.int64)
        d = np.linalg.norm(local[free, :2] - local[out[i], :2], axis=1) if len(free) else np.zeros(0)
        if not len(free) or d.min() > REACH * es:
            missed.append(name)
            continue
        pick = int(free[np.argmin(d)])
        taken.discard(out[i])
        out[i] = pick
        taken.add(pick)
    if missed:
        logger.info("lip contact: none within %.2f ES of %s (%d contact vertices); kept the fit's", REACH,
                    ", ".join(missed), len(contact))
    return out, missed


def corner_doubts(names: Sequence[str], chosen: Sequence[int], vertices: np.ndarray, face: Face,
                  triangles: np.ndarray) -> list[dict]:
    """Doubts for the inner corners of a closed mouth (the caller knows it has no slit) that are not on the lips'
    contact: where the lips touch nowhere near them, their place is the coarse fit's."""
    names = tuple(names)
    if not all(n in names for n in (*INNER_CORNERS, "eye_inner_L", "eye_inner_R")):
        return []
    v = np.asarray(vertices, np.float64)
    at = {n: int(chosen[names.index(n)]) for n in (*INNER_CORNERS, "eye_inner_L", "eye_inner_R")}
    es = float(np.linalg.norm(face.to_frame(v[at["eye_inner_L"]])[:2] - face.to_frame(v[at["eye_inner_R"]])[:2]))
    contact = set(lip_contact(v, face, triangles, v[[at[n] for n in INNER_CORNERS]].mean(0), es).tolist()) \
        if es > 0 else set()
    return [{"points": [name], "why": "not where the lips touch (a closed mouth's inner corner lies under the upper "
                                      "lip, on the lower lip's skin facing up, and none was found near it): placed "
                                      "by the coarse fit, often on the outer lip beside it; the lip rolls and "
                                      "presses lean on it"} for name in INNER_CORNERS if at[name] not in contact]
