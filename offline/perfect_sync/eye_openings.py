"""Where a face's eyes open, seen from the front, and the eye's control points put on the lid margins.

A coarse fit of the source's control points to the skin (:func:`~.proposal.fit_points`) lands the lid
points near the lids, but on a head of other proportions a few millimetres off: on the lid above the
margin, or inside the fold. Every later step leans on them (a blink puts the upper lid points onto the
lower ones), so a lid point 4 mm above a 7 mm opening makes the blink drive the lid through the
lower one. The opening itself is a plain geometric fact, found here without the source:

the skin is drawn into a depth buffer in the face frame, looking along −z, in a window about each eye's
fitted points. Where the eye opens, the front-most skin is either missing (a hole: the MediaPipe face)
or far behind the skin both above and below it in the same column (the socket behind an eyeball: ICT), so
the opening is the connected region of such pixels at the eye's fitted centre. Its outer end is the eye's
outer corner (wherever the fit put it: a fit high or narrower than the eye would keep it inside the opening);
the inner corner is the opening's pixel nearest the fit's, the fit first moved as the outer corner moved where
it lies off the opening (a crease of the MediaPipe-like heads joins the opening's inner end and runs on towards
the nose, so that end is not the corner); in each column its top is the upper lid's margin, its bottom the lower's. The
eye's six points are put at the source's places along the eye (their fraction of the corner-to-corner
width) on those margins, each on the skin vertex seen from the front that lies nearest.

An opening that is not eye-like (narrower than 0.4 inner-eye distances or wider than 2, taller than 0.8,
touching the window's edge, or none: eyes drawn shut, a face with no openings) leaves the fit's points
as they were.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.front_depth import depth_buffer, valley

logger = logging.getLogger(__name__)

EYE_POINTS = ("eye_inner", "eye_outer", "lid_upper_inner", "lid_upper_outer", "lid_lower_inner", "lid_lower_outer")
PIXELS_PER_ES = 60  # depth-buffer resolution: pixels per inner-eye distance (ES)
WINDOW = (1.0, 0.7)  # the window about the eye's fitted centre: half width, half height (ES)
DEEP = 0.15  # skin this many ES behind the front-most skin above or below it in its column is not a lid
COLUMN = 0.3  # ... within this many ES up or down
WIDTH_RANGE = (0.4, 2.0)  # an eye opening's width (ES)
MAX_HEIGHT = 0.8  # ... and its largest height (ES)
CORNER_BEYOND = 0.12  # a fitted inner corner this many ES past the opening's end along the eye is kept; further
# off the opening, it is first moved as the outer corner moved
END_COLUMNS = 2  # an opening's outer end: the mean row of its columns this many pixels from its extreme one
VISIBLE = 0.05  # a vertex within this many ES of the front-most skin at its pixel is seen from the front


def eye_opening(local: np.ndarray, triangles: np.ndarray, centre: np.ndarray, es: float) -> dict | None:
    """The opening of the eye whose fitted points are centred at ``centre`` (x, y face frame), or None when there
    is no eye-like one: {"open": its pixels (rows up, columns across), "grid": (x0, y0, pixel size) of the
    pixels' first centre, "zbuf": the skin's depth buffer}."""
    h = es / PIXELS_PER_ES
    half_w, half_h = WINDOW[0] * es, WINDOW[1] * es
    x0, y0 = centre[0] - half_w, centre[1] - half_h
    shape = (int(2 * half_h / h) + 1, int(2 * half_w / h) + 1)
    zbuf = depth_buffer(local, triangles, x0, y0, h, shape)
    # a valley between lids (a slope under a brow ridge is deep on one side only); a hole is open anywhere
    opening = ~np.isfinite(zbuf) | (valley(zbuf, max(int(COLUMN * es / h), 1)) > DEEP * es)
    labels, count = ndimage.label(opening)
    if not count:
        return None
    r, c = int(round(half_h / h)), int(round(half_w / h))
    rows, cols = np.nonzero(labels)
    pick = labels[rows, cols][np.argmin((rows - r) ** 2 + (cols - c) ** 2)]
    rr, cc = np.nonzero(labels == pick)
    width, height = (np.ptp(cc) + 1) * h / es, (np.ptp(rr) + 1) * h / es
    edge = rr.min() == 0 or cc.min() == 0 or rr.max() == shape[0] - 1 or cc.max() == shape[1] - 1
    if edge or not WIDTH_RANGE[0] <= width <= WIDTH_RANGE[1] or height > MAX_HEIGHT:
        logger.info("eye opening near (%.2f, %.2f): not eye-like (%.2f x %.2f ES%s); the fit's points are kept",
                    centre[0], centre[1], width, height, ", at the window's edge" if edge else "")
        return None
    return {"open": labels == pick, "grid": (x0, y0, h), "zbuf": zbuf}


def _margins(opening: np.ndarray, column: int, row: float) -> tuple[float, float]:
    """(top, bottom) row edges of the run of open pixels in ``column`` nearest ``row`` (the eye's line there): a
    fold that joins the opening elsewhere in the column is not the lid."""
    open_rows = np.flatnonzero(opening[:, column])
    if not len(open_rows):
        return row, row
    runs = np.split(open_rows, np.flatnonzero(np.diff(open_rows) > 1) + 1)
    best = min(runs, key=lambda run: 0.0 if run[0] <= row <= run[-1] else min(abs(run[0] - row), abs(run[-1] - row)))
    return best[-1] + 0.5, best[0] - 0.5


def eye_points(source_positions: np.ndarray, names: Sequence[str], fitted: np.ndarray, vertices: np.ndarray,
               face: Face, skin_triangles: np.ndarray, candidates: np.ndarray) -> dict:
    """{control-point name: skin vertex} for the eye points of each eye whose opening is found (see the module
    doc); ``fitted`` (n_c, 3) the coarse fit's places (world), ``candidates`` the skin vertices a point may take."""
    names = tuple(names)
    idx = {n: i for i, n in enumerate(names)}
    src = np.asarray(source_positions, np.float64)
    local = face.to_frame(np.asarray(vertices, np.float64))
    fit = face.to_frame(np.asarray(fitted, np.float64))
    if "eye_inner_L" not in idx or "eye_inner_R" not in idx:
        return {}
    es = float(np.linalg.norm(fit[idx["eye_inner_L"], :2] - fit[idx["eye_inner_R"], :2]))
    if es <= 0:
        return {}
    cand = np.asarray(candidates, np.int64)
    out: dict = {}
    for side in ("L", "R"):
        need = [f"{n}_{side}" for n in EYE_POINTS]
        if not all(n in idx for n in need):
            continue
        centre = fit[[idx[n] for n in need], :2].mean(0)
        found = eye_opening(local, skin_triangles, centre, es)
        if found is None:
            continue
        x0, y0, h = found["grid"]
        zbuf, opening = found["zbuf"], found["open"]
        col = np.clip(np.round((local[cand, 0] - x0) / h).astype(np.int64), 0, zbuf.shape[1] - 1)
        row = np.clip(np.round((local[cand, 1] - y0) / h).astype(np.int64), 0, zbuf.shape[0] - 1)
        # on the skin seen from the front, not in the opening (the socket behind an eyeball is seen there too)
        seen = cand[(local[cand, 2] >= zbuf[row, col] - VISIBLE * es) & ~opening[row, col]]
        rr, cc = np.nonzero(opening)
        corner = {}
        middle = cc.mean()
        # the outer corner: the opening's end on the fit's outer corner's side (the rows of its last columns), where
        # the lids meet sharply; the fit's corner may lie anywhere about it (inside the opening when the eye is wider
        # than the fit, above it when the fit is high), so the end is taken, not the pixel nearest the fit's
        f_out = (fit[idx[f"eye_outer_{side}"], :2] - (x0, y0)) / h
        toward = 1.0 if f_out[0] > middle else -1.0
        end = cc.max() if toward > 0 else cc.min()
        corner["eye_outer"] = np.array([end, rr[np.abs(cc - end) <= END_COLUMNS].mean()], np.float64)
        # the inner corner: the opening's pixel nearest the fit's, the fit's eye first moved as its outer corner
        # moved (a crease may join the opening's inner end and run on to the nose, so its end is not the corner)
        f = (fit[idx[f"eye_inner_{side}"], :2] - (x0, y0)) / h
        if np.sqrt(((cc - f[0]) ** 2 + (rr - f[1]) ** 2).min()) * h > CORNER_BEYOND * es:  # off the opening
            f = f + corner["eye_outer"] - f_out
        k = int(np.argmin((cc - f[0]) ** 2 + (rr - f[1]) ** 2))
        corner["eye_inner"] = np.array([cc[k], rr[k]], np.float64)
        # ... unless the fit's lies just beyond the opening's end: there the lids meet over the caruncle in a
        # shallow crease (ICT's inner corner lies 0.08 ES past its opening's end), so the end is only the least
        # reach of the eye
        beyond = (f[0] - cc[k]) * np.sign(cc[k] - middle)
        if 0 < beyond * h <= CORNER_BEYOND * es:
            corner["eye_inner"] = f
        span = corner["eye_outer"] - corner["eye_inner"]
        if not WIDTH_RANGE[0] <= abs(span[0]) * h / es <= WIDTH_RANGE[1]:
            logger.info("eye %s: corners %.2f ES apart; the fit's points are kept", side, abs(span[0]) * h / es)
            continue
        s_in, s_out = src[idx[f"eye_inner_{side}"]], src[idx[f"eye_outer_{side}"]]
        for name in EYE_POINTS:
            key = f"{name}_{side}"
            if name in corner:
                place = corner[name]
            else:  # the source's fraction of the way between the corners, on the margin of its lid
                u = (src[idx[key], 0] - s_in[0]) / (s_out[0] - s_in[0])
                p = corner["eye_inner"] + u * span
                top, bottom = _margins(opening, int(round(p[0])), p[1])
                place = np.array([p[0], top if "upper" in name else bottom])
            world = place * h + (x0, y0)
            out[key] = int(seen[np.argmin(np.linalg.norm(local[seen, :2] - world, axis=1))])
    return out
