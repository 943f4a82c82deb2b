"""Where a face's lips meet, seen from the front, and the mouth's control points placed about that line.

The lips meet in a crease that is a valley of the skin's depth along the face's up axis
(:mod:`.front_depth`), deeper than the lips on either side and, where the mouth is open or the skin has a
slit, a hole. The slit is the connected region of the valley at the coarse fit's mouth centre; its ends
are the mouth's corners (wherever the fit's corners lie: on a mouth wider than the fit, the slit's pixel
nearest the fit's corner kept it up to 0.8 cm inside the mouth; a crease of the cheek joining the slit's end
would carry the corner with it, which none of the measured heads has), and in each column its deepest pixel is
on the lip line.

The slit's ends are where the crease fades, a little inside the corners (``CORNER_PAST``). The
source's mouth points keep their place relative to the source's corners and line: along the mouth
by their fraction of the corner-to-corner width, across it by their height above or below the source's
line (through its corners and the middle of its inner lips), scaled as the coarse fit scaled the lips'
height (the slit says nothing of it). A slit that
is not mouth-like (narrower than 0.6 inner-eye distances or wider than 3, at the window's edge, or none)
leaves the fit's points as they were.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.front_depth import depth_buffer, valley

logger = logging.getLogger(__name__)

MOUTH_PREFIXES = ("mouth_corner", "mouth_inner", "lip_upper", "lip_lower")
PIXELS_PER_ES = 60
WINDOW = (1.4, 0.6)  # half width, half height about the fit's mouth centre (ES)
CREASE = 0.02  # the lips' crease: this many ES behind the skin above and below it ...
REACH = 0.17  # ... within this many ES up or down
WIDTH_RANGE = (0.6, 3.0)  # a mouth's width (ES)
# the corner points lie this many ES past the end of the crease (measured on the source, the ICT head: its
# crease fades below CREASE 0.07 cm = 0.019 ES inside its mouth corners)
CORNER_PAST = 0.02
AGREE = 0.03  # a point found within this many ES of the fit's place keeps the fit's (about two pixels)


def is_mouth_point(name: str) -> bool:
    """Whether ``name`` is one of the mouth's points this module places."""
    return any(name == p or name.startswith(p + "_") for p in MOUTH_PREFIXES)


def mouth_places(source_positions: np.ndarray, names: Sequence[str], fitted: np.ndarray, vertices: np.ndarray,
                 face: Face, skin_triangles: np.ndarray) -> dict:
    """{control-point name: place (3,) world} for the mouth's points when the slit is found (see the module
    doc), on the front-most skin; ``fitted`` (n_c, 3) the coarse fit's places (world)."""
    names = tuple(names)
    idx = {n: i for i, n in enumerate(names)}
    need = ("mouth_corner_L", "mouth_corner_R", "lip_upper_inner", "lip_lower_inner", "eye_inner_L", "eye_inner_R")
    if not all(n in idx for n in need):
        return {}
    src = np.asarray(source_positions, np.float64)
    local = face.to_frame(np.asarray(vertices, np.float64))
    fit = face.to_frame(np.asarray(fitted, np.float64))
    es = float(np.linalg.norm(fit[idx["eye_inner_L"], :2] - fit[idx["eye_inner_R"], :2]))
    if es <= 0:
        return {}
    h = es / PIXELS_PER_ES
    centre = 0.5 * (fit[idx["mouth_corner_L"], :2] + fit[idx["mouth_corner_R"], :2])
    x0, y0 = centre[0] - WINDOW[0] * es, centre[1] - WINDOW[1] * es
    shape = (int(2 * WINDOW[1] * es / h) + 1, int(2 * WINDOW[0] * es / h) + 1)
    zbuf = depth_buffer(local, skin_triangles, x0, y0, h, shape)
    depth = valley(zbuf, max(int(REACH * es / h), 1))
    crease = ~np.isfinite(zbuf) | (depth > CREASE * es)
    labels, count = ndimage.label(crease)
    if not count:
        return {}
    rows, cols = np.nonzero(labels)
    r, c = (centre[1] - y0) / h, (centre[0] - x0) / h
    pick = labels[rows, cols][np.argmin((rows - r) ** 2 + (cols - c) ** 2)]
    rr, cc = np.nonzero(labels == pick)
    edge = rr.min() == 0 or cc.min() == 0 or rr.max() == shape[0] - 1 or cc.max() == shape[1] - 1
    deep = np.where(labels == pick, np.where(np.isfinite(depth), depth, 1e30), -np.inf)
    corner = {}
    middle = cc.mean()
    for side in ("L", "R"):  # the column of the slit's end on the fit's corner's side, a little further out
        f = (fit[idx[f"mouth_corner_{side}"], :2] - (x0, y0)) / h  # (CORNER_PAST), on the deepest row there
        k = int(np.argmax(cc) if f[0] > middle else np.argmin(cc))
        corner[side] = np.array([cc[k] + np.sign(cc[k] - middle) * CORNER_PAST * es / h,
                                 np.argmax(deep[:, cc[k]])], np.float64)
    width = abs(corner["L"][0] - corner["R"][0]) * h / es
    if edge or not WIDTH_RANGE[0] <= width <= WIDTH_RANGE[1]:
        logger.info("mouth slit: not mouth-like (%.2f ES wide%s); the fit's points are kept", width,
                    ", at the window's edge" if edge else "")
        return {}
    line_cols = np.arange(int(min(corner["L"][0], corner["R"][0])), int(max(corner["L"][0], corner["R"][0])) + 1)
    line_rows = np.array([np.argmax(deep[:, k]) if np.isfinite(deep[:, k].max()) else np.nan for k in line_cols])
    ok = ~np.isnan(line_rows)
    if ok.sum() < 2:
        return {}

    def line_row(col: float) -> float:  # the target's lip line, through its corners
        xs = np.concatenate([[corner["R"][0]], line_cols[ok], [corner["L"][0]]])
        ys = np.concatenate([[corner["R"][1]], line_rows[ok], [corner["L"][1]]])
        order = np.argsort(xs)
        return float(np.interp(col, xs[order], ys[order]))

    s_r, s_l = src[idx["mouth_corner_R"]], src[idx["mouth_corner_L"]]
    s_mid = 0.5 * (src[idx["lip_upper_inner"]] + src[idx["lip_lower_inner"]])

    def source_line(x: float) -> float:  # the source's, through its corners and its inner lips' middle
        return float(np.interp(x, [s_r[0], s_mid[0], s_l[0]], [s_r[1], s_mid[1], s_l[1]]))

    scale = (corner["L"][0] - corner["R"][0]) / (s_l[0] - s_r[0])  # target pixels per source unit, across
    # up and down: the lips' height is no part of the slit; the coarse fit's own scale of it (its per-axis fit)
    tall = [n for n in ("lip_upper", "lip_lower") if n in idx]
    s_tall = src[idx[tall[0]], 1] - src[idx[tall[-1]], 1] if len(tall) == 2 else 0.0
    f_tall = fit[idx[tall[0]], 1] - fit[idx[tall[-1]], 1] if len(tall) == 2 else 0.0
    up_scale = f_tall / s_tall / h if s_tall > 0 and f_tall > 0 else scale
    out = {}
    for name in names:
        if not is_mouth_point(name):
            continue
        p = src[idx[name]]
        if name in ("mouth_corner_L", "mouth_corner_R"):
            px = corner[name[-1]]
        else:
            col = corner["R"][0] + (p[0] - s_r[0]) * scale
            px = np.array([col, line_row(col) + (p[1] - source_line(p[0])) * up_scale])
        rc = np.clip(np.round(px[::-1]).astype(np.int64), 0, np.array(shape) - 1)
        z = zbuf[rc[0], rc[1]]
        if not np.isfinite(z) or crease[rc[0], rc[1]]:  # in the crease the front-most skin is inside the mouth
            z = fit[idx[name], 2]
        place = np.array([x0 + h * px[0], y0 + h * px[1], z])
        if np.linalg.norm(place[:2] - fit[idx[name], :2]) <= AGREE * es:
            continue  # the fit agrees within the slit's resolution: its place (and depth) stands
        out[name] = (place + face.origin) @ face.frame
    return out
