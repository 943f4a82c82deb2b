"""A cloned blink's lids meet along the whole lid, measured on the character itself.

The blink's upper lid control points are put onto the lower ones (:func:`~.transfer.close_lids`), but
between them the lid moves as the elastic clone carries it, and that follows where the source's points
sit along the lid. On a head whose lid curves differently, or whose points are proposed at other places
along the lid than the source's, the middle of the lid stays open (a head warped 1.5 times towards the
MediaPipe face's proportions: 0.16 cm left of a 0.62 cm gap while the points themselves met).

Here the lid is measured on the character's own rest skin, not on the points: its eye opening seen from the
front (:func:`~.eye_openings.eye_opening`) gives, column by column across the eye from its inner corner point
to the opening's outer end, the upper and the lower lid margin (the run of the opening at the eye's line). The
lids meet at the inner corner over the caruncle in a shallow crease, so an opening beyond that point is a
crease by the nose, not a lid (on ICT's proportions variant it ran 0.7 cm on); the outer corner is a sharp
meeting of the lids, where the opening's end is the corner (a proposed outer corner can be far off: 1.8 cm on
the actor's-face variant, whose outer lid then stayed open). Each is snapped to the nearest skin vertex seen
from the front that lies on the lid's front (within :data:`DEPTH` of the front-most skin just beyond the
margin in its column: the socket behind an eyeball, seen through the opening's edge, is no margin).

After the clone, the gap left in each column (along the face's up) is held between 0 (the lids meet) and
``closed`` of its rest gap: where it is wider (the lid left open) or below 0 (driven through the lower lid),
the upper lid is moved by the difference; where the clone already closes the lid it is left as cloned. The
correction is a field that is the column's value on the upper margin vertex and fades (a half cosine) to
zero :data:`FADE` inner-eye distances above it, across the eye to zero just past its corners, and is zero on
the lower lid (below the opening's middle line) and deep behind the lids. Other shapes that close the same
lid part of the way (a squint) are left as the clone made them: their lid is not meant to meet.

A face without an eye-like opening (eyes drawn shut, a decal eye) gets no field: said in the log.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage

from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.perfect_sync.eye_openings import COLUMN, EYE_POINTS, VISIBLE, _margins, eye_opening

logger = logging.getLogger(__name__)

# A blink's lid margins stay this fraction of their rest gap apart in the middle: the design head's own (ICT's
# true eyeBlink: 0.146 of 0.993 cm at the mid-lid skin; the rounded margins and the lashes meet in front of it)
SEALED_GAP = 0.15
FADE = 0.3  # inner-eye distances above the upper margin at which the correction has faded to zero
PAST_CORNER = 0.08  # ... and past each corner across the eye
DEPTH = 0.2  # skin more than this many inner-eye distances behind the upper margin is the socket, not the lid
BLINKS = (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R"))


def lid_margins(local: np.ndarray, skin_triangles: np.ndarray, skin: np.ndarray, points: ControlPoints) -> dict:
    """{"L"/"R": {"upper", "lower": (k,) skin vertices on the upper lid margin across the eye and the lower lid
    margin vertex each faces, "x": (k,) the upper ones' places across the eye (ascending), "es": inner-eye
    distance}} of each eye whose opening is eye-like;
    ``local`` (n, 3) the vertices in the face frame, ``skin`` the vertices a margin may take."""
    if not all(f"eye_inner_{s}" in points.names for s in "LR"):
        return {}
    es = float(np.linalg.norm(local[points.vertex("eye_inner_L"), :2] - local[points.vertex("eye_inner_R"), :2]))
    if es <= 0:
        return {}
    out: dict = {}
    for side in ("L", "R"):
        need = [f"{n}_{side}" for n in EYE_POINTS]
        if not all(n in points.names for n in need):
            continue
        centre = local[[points.vertex(n) for n in need], :2].mean(0)
        found = eye_opening(local, skin_triangles, centre, es)
        if found is None:
            logger.info("eye %s: no eye-like opening; the blink's lids are left as cloned", side)
            continue
        x0, y0, h = found["grid"]
        zbuf, opening = found["zbuf"], found["open"]
        cand = np.asarray(skin, np.int64)
        col = np.round((local[cand, 0] - x0) / h).astype(np.int64)
        row = np.round((local[cand, 1] - y0) / h).astype(np.int64)
        inside = (col >= 0) & (col < zbuf.shape[1]) & (row >= 0) & (row < zbuf.shape[0])
        cand, col, row = cand[inside], col[inside], row[inside]
        # seen from the front: near the front-most skin at its pixel, or, on a pixel of the opening (a margin
        # vertex on a hole's very edge falls in one half the time), near the skin beside it
        beside = ndimage.maximum_filter(np.where(opening, -np.inf, zbuf), size=3)
        front = np.where(opening[row, col], beside[row, col], zbuf[row, col])
        seen = cand[np.isfinite(front) & (local[cand, 2] >= front - VISIBLE * es)]
        if not len(seen):
            continue
        pairs: dict = {}  # upper margin vertex -> (its column's distance, the lower margin vertex)
        reach = max(int(COLUMN * es / h), 1)
        middle = int(round(np.flatnonzero(opening.any(axis=1)).mean()))
        inner, outer = local[points.vertex(f"eye_inner_{side}"), 0], local[points.vertex(f"eye_outer_{side}"), 0]
        for c in np.flatnonzero(opening.any(axis=0)):
            x = x0 + c * h
            if (x - inner) * np.sign(outer - inner) <= 0:
                continue  # the lids meet at the inner corner; an opening beyond it is a crease by the nose
            top, bottom = _margins(opening, c, middle)  # the run of the opening at the eye's line, not a fold
            ends = []
            for edge, rows in ((top, slice(int(top + 0.5), int(top + 0.5) + reach)),
                               (bottom, slice(max(int(bottom - 0.5) - reach + 1, 0), int(bottom - 0.5) + 1))):
                lid = zbuf[rows, c]  # the lid's front beside the opening: a margin vertex lies on it, not in the
                lid = lid[np.isfinite(lid)]  # socket seen through the opening's edge
                near = seen[local[seen, 2] >= (lid.max() if len(lid) else -np.inf) - DEPTH * es]
                if not len(near):
                    break
                ends.append(int(near[np.argmin(np.hypot(local[near, 0] - x, local[near, 1] - (y0 + edge * h)))]))
            if len(ends) < 2:
                continue
            up, low = ends
            off = abs(local[up, 0] - x)
            if up != low and (up not in pairs or off < pairs[up][0]):
                pairs[up] = (off, low)  # several columns snap to one vertex: the column nearest it pairs it
        if len(pairs) >= 2:
            ups = np.asarray(sorted(pairs, key=lambda k: local[k, 0]), np.int64)
            out[side] = {"x": local[ups, 0], "upper": ups, "lower": np.asarray([pairs[k][1] for k in ups], np.int64),
                         "es": es}
    return out


def seal_field(local: np.ndarray, d_local: np.ndarray, region: np.ndarray, margin: dict,
               closed: float) -> tuple[np.ndarray, float]:
    """(the upper lid's correction (len(region), 3) in the face frame, the largest column correction) that brings
    each column's shaped gap (``d_local``: the shape's deltas (n, 3) in the face frame) between 0 and ``closed`` of
    its rest gap; ``region`` the skin vertices the field may move (see the module doc)."""
    x, up, low, es = margin["x"], margin["upper"], margin["lower"], margin["es"]
    rest = local[up, 1] - local[low, 1]
    shaped = rest + d_local[up, 1] - d_local[low, 1]
    need = np.clip(shaped, 0.0, closed * rest) - shaped  # along up: negative brings the upper lid down
    order = np.argsort(x)
    x, need = x[order], need[order]
    y_up, y_low, z_up = local[up[order], 1], local[low[order], 1], local[up[order], 2]
    ends = [x[0] - PAST_CORNER * es, x[-1] + PAST_CORNER * es]
    p = local[region]
    amount = np.interp(p[:, 0], [ends[0], *x, ends[1]], [0.0, *need, 0.0], left=0.0, right=0.0)
    top = np.interp(p[:, 0], x, y_up)
    middle = 0.5 * (top + np.interp(p[:, 0], x, y_low))
    t = np.clip((p[:, 1] - top) / (FADE * es), 0.0, 1.0)
    weight = 0.5 * (1.0 + np.cos(np.pi * t))
    weight[(p[:, 1] < middle) | (p[:, 2] < np.interp(p[:, 0], x, z_up) - DEPTH * es)] = 0.0
    field = np.zeros((len(region), 3))
    field[:, 1] = weight * amount
    at = np.full(len(local), -1, np.int64)
    at[region] = np.arange(len(region))
    own = at[up[order]]  # each margin vertex closes its own column exactly (two may share a place across the eye)
    field[own[own >= 0], 1] = need[own >= 0]
    return field, float(np.abs(need).max())


def seal_blink(d: np.ndarray, key: str, local: np.ndarray, region: np.ndarray, margins: dict, frame: np.ndarray,
               closed: float | None = None) -> float | None:
    """Correct the blink ``key`` (its deltas ``d`` (n, 3), world, in place) so that its lids meet along the whole
    lid (:func:`seal_field`; ``local`` the rest vertices in the face frame whose rows are ``frame``, ``margins``
    from :func:`lid_margins` on them). Returns the largest column correction (units), or None when ``key`` is no
    blink or its eye has no margins."""
    side = dict(BLINKS).get(key)
    if side is None or side not in margins:
        return None
    closed = SEALED_GAP if closed is None else closed
    field, largest = seal_field(local, np.asarray(d, np.float64) @ frame.T, region, margins[side], closed)
    d[region] += (field @ frame).astype(d.dtype)
    return largest
