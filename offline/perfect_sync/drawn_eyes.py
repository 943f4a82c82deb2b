"""A decal eye closing and narrowing as a drawn eye does, rather than by the landmark field.

A decal eye closes in the blinks by a drawn eye's own rule rather than by
the field (:func:`decal_blink`): the lids meet on the line joining the
eye's corners (the ends of its outline, where they meet at rest), every
vertex of the eye squashed onto that line to ``CLOSED`` of its rest height
about it (a thin outline is left), and what lies inside the eye (iris,
white) is covered rather than folded: it goes back along the line of sight
behind the skin in front of it, by its stand-off plus ``HIDDEN`` of the
eye's width. ``CLOSED`` and ``HIDDEN`` are chosen constants (5 %), not
fitted to a character: Godette's blink cosine moves 0.72–0.74 for
``HIDDEN`` from 0 to 0.2. The outline above the line is lowered as a
drawn stroke (:func:`closed_heights`): its edge nearest the line comes to
``CLOSED`` of its height, what lies beyond keeps up to ``LINE`` (10 %, a
chosen constant: about the thickness of Godette's lash stroke at rest,
0.012 of her 0.087 eye) of the eye's height and ``CLOSED`` of the rest.
Squashed whole to 5 % her closed lash read as a faint broken hair-line in
the take's side-by-side; lowering each column whole, keeping the lashes'
tips, read as a line too but took her blink cosine to 0.67, below the
goal (with ``LINE``: 0.73, 0.74).

It narrows the same drawn way in every other shape that moves the
lids (:func:`decal_narrow`; eyeSquint, browDown, cheekSquint; eyeWide
opens it): toward its closed place, what lies above the corner line by the
fraction of the blink's way that the source's shape lowers its upper lid
points, what lies below by the fraction it raises the lower ones
(:func:`lid_fractions`, measured on the source: ICT's eyeSquint 0.03 and
0.42), the iris with it; a shape that moves no lid point leaves the eye.
The landmark field squashed the lash outline into a V and pulled the iris
(in the kit's take the blinks come with eyeSquint, eyeLookDown, browDown
and cheekSquint at partial weights).
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.pieces import CORNER, Pieces
from facepuppet.offline.perfect_sync.triangles import skin_front_depth

CLOSED = 0.05  # a decal blink leaves this fraction of each vertex's rest height about the closing line
STROKE = 0.05  # a drawn eye's outline column: its vertices within this fraction of the eye's width across
LINE = 0.1  # a closed drawn eye's outline keeps up to this fraction of the eye's height of its stroke
HIDDEN = 0.05  # a closed drawn eye's iris goes this fraction of the eye's width behind the skin (past its stand-off)


def eye_inside(pieces: Pieces, local: np.ndarray, side: str) -> np.ndarray:
    """The vertices of the ``side`` decal eye's pieces lying wholly within its largest piece's box (iris, pupil,
    highlights, the eye's white; not the outline and lashes reaching beyond it). ``local``: face-frame positions."""
    members, (x0, x1, y0, y1) = pieces.eyes[side]
    labels = pieces.labels[members]
    p = local[members]
    within = (p[:, 0] >= x0 - 1e-9) & (p[:, 0] <= x1 + 1e-9) & (p[:, 1] >= y0 - 1e-9) & (p[:, 1] <= y1 + 1e-9)
    inside = [lab for lab in np.unique(labels) if within[labels == lab].all()]
    return members[np.isin(labels, inside)]


def drawn_corners(pieces: Pieces, local: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(inner, outer) corner (x, y) in the face frame of the ``side`` decal eye: the mean place of its pieces'
    vertices within ``CORNER`` of its width from its innermost / outermost point (the ends of its outline)."""
    members, _ = pieces.eyes[side]
    p = local[members, :2]
    sign = 1.0 if side == "L" else -1.0
    across = sign * p[:, 0]
    reach = CORNER * float(np.ptp(across))
    inner = p[across <= across.min() + reach].mean(0)
    outer = p[across >= across.max() - reach].mean(0)
    return inner, outer


def _above_corner_line(pieces: Pieces, local: np.ndarray, side: str) -> np.ndarray:
    """Height (face-frame y) of each vertex of the ``side`` decal eye's pieces above the line through its drawn
    corners (:func:`drawn_corners`); negative below it."""
    members, _ = pieces.eyes[side]
    inner, outer = drawn_corners(pieces, local, side)
    slope = (outer[1] - inner[1]) / (outer[0] - inner[0]) if abs(outer[0] - inner[0]) > 1e-12 else 0.0
    return local[members, 1] - (inner[1] + slope * (local[members, 0] - inner[0]))


def closed_heights(pieces: Pieces, local: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(rest, closed) height of each vertex of the ``side`` decal eye's pieces above the line through its drawn
    corners (:func:`_above_corner_line`; negative below it). Closed, what lies inside the eye (:func:`eye_inside`)
    keeps ``CLOSED`` of its height, and so does what of the outline lies below the line (a lash tail at the
    outer corner); the outline above it comes down onto the line as a drawn stroke: in each column (its
    vertices above the line within ``STROKE`` of the eye's width across) the edge nearest the line keeps
    ``CLOSED`` of its height, what lies beyond that edge keeps up to ``LINE`` of the eye's height of its distance
    from it and ``CLOSED`` of the rest (the lashes' tips), so that the closed eye is a visible line rather than a
    hair-line (Godette: her lash strip squashed whole to 5 % read as nothing in the take's side-by-side)."""
    members, (_, _, y0, y1) = pieces.eyes[side]
    rest = _above_corner_line(pieces, local, side)
    closed = CLOSED * rest
    outline = ~np.isin(members, eye_inside(pieces, local, side))
    x = local[members, 0]
    reach = STROKE * float(np.ptp(x))
    keep = LINE * (y1 - y0)
    for k in np.flatnonzero(outline & (rest > 0)):
        col = outline & (np.abs(x - x[k]) <= reach) & (rest > 0)
        edge = float(rest[col].min())
        beyond = rest[k] - edge
        closed[k] = CLOSED * edge + min(beyond, keep) + CLOSED * max(beyond - keep, 0.0)
    return rest, closed


def decal_blink(pieces: Pieces, face: Face, vertices: np.ndarray, skin_triangles: np.ndarray,
                side: str) -> tuple[np.ndarray, np.ndarray]:
    """The closed drawn eye of ``side``: (its pieces' vertices, their displacements (m, 3) in world axes).

    A drawn eye's lids meet on the curve joining its corners, where they meet at rest already (a closed eye
    is drawn as the line from corner to corner): every vertex of the eye's pieces comes toward the line through
    the corners (:func:`drawn_corners`) along the face's up, to its closed height (:func:`closed_heights`), the
    upper part down, the lower part up, the outline so keeping a line. What lies inside the
    eye (:func:`eye_inside`: the iris and the eye's white) is covered instead, not folded: it keeps its shape
    and goes back along the line of sight behind the skin in front of it (:func:`skin_front_depth`), by its
    stand-off plus ``HIDDEN`` of the eye's width."""
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    members, (x0, x1, _, _) = pieces.eyes[side]
    rest, closed = closed_heights(pieces, local, side)
    d = np.zeros((len(members), 3))
    d[:, 1] = closed - rest
    hide = np.isin(members, eye_inside(pieces, local, side))
    d[hide, 1] = 0.0  # covered, not folded: what lies inside the eye keeps its shape and goes behind the skin
    if hide.any() and len(skin_triangles):
        at = local[members[hide]]
        front = skin_front_depth(at[:, :2], local, skin_triangles)
        back = np.where(np.isnan(front), 0.0, np.maximum(at[:, 2] - front, 0.0) + HIDDEN * abs(x1 - x0))
        d[hide, 2] -= back
    return members, d @ face.frame


def lid_fractions(source_positions: np.ndarray, names: tuple, params: np.ndarray, shape_names: tuple,
                     key: str, side: str) -> tuple[float, float]:
    """(upper, lower): how far the source's shape ``key`` brings the ``side`` eye's upper lid down and its lower
    lid up, each as a fraction of the gap its blink closes (the mean over the inner and outer lid points; each in
    [-1, 1], negative where the shape opens the eye (eyeWide); (0, 0) without the lid points or the blink).
    Measured on the source's parameters, not a chosen constant: ICT's eyeSquint raises the lower lid 0.42 of the
    blink's closure and lowers the upper 0.03; its browDown lowers the upper lid 0.14, its cheekSquint raises
    the lower lid 0.45."""
    idx = {n: i for i, n in enumerate(names)}
    blink = {"L": "eyeBlinkLeft", "R": "eyeBlinkRight"}[side]
    if key not in shape_names or blink not in shape_names:
        return 0.0, 0.0
    prm = np.asarray(params, np.float64)
    sq, bl = prm[shape_names.index(key)], prm[shape_names.index(blink)]
    up, low = [], []
    for part in ("inner", "outer"):
        i, j = idx.get(f"lid_upper_{part}_{side}"), idx.get(f"lid_lower_{part}_{side}")
        if i is None or j is None:
            continue
        closure = bl[j, 1] - bl[i, 1]  # the blink's closing of the gap (upper down, lower up)
        if closure <= 1e-12:
            continue
        up.append(-sq[i, 1] / closure)
        low.append(sq[j, 1] / closure)
    if not up:
        return 0.0, 0.0
    return float(np.clip(np.mean(up), -1.0, 1.0)), float(np.clip(np.mean(low), -1.0, 1.0))


def decal_narrow(pieces: Pieces, face: Face, vertices: np.ndarray, side: str, upper: float,
                 lower: float) -> tuple[np.ndarray, np.ndarray]:
    """The narrowed (or, by negative fractions, opened) drawn eye of ``side``: (its pieces' vertices, their
    displacements (m, 3) in world axes). A drawn eye narrows the way it closes (:func:`decal_blink`): toward its
    closed place (:func:`closed_heights`) along the face's up, what lies above the corner line by ``upper`` of
    the blink's way there, what lies below by ``lower`` (:func:`lid_fractions`), the iris and white with it (a
    squint does not hide them); the outline's tail below the line stays (it is the upper stroke's)."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    members, _ = pieces.eyes[side]
    rest, closed = closed_heights(pieces, local, side)
    d = np.zeros((len(members), 3))
    d[:, 1] = (closed - rest) * np.where(rest > 0, upper, lower)
    tail = (rest < 0) & ~np.isin(members, eye_inside(pieces, local, side))
    d[tail] = 0.0  # the upper stroke's tail below the corner: the lower lid's rise moves what lies inside the eye
    return members, d @ face.frame
