"""Whether the outer lip points lie on the lips' outline: a doubt for each one that does not.

The mouth's corners and inner lips are found on the skin (:mod:`.mouth_slit`, :mod:`.lip_contact`), but
the outer lip points are only carried there at the source's lip height, scaled as the coarse fit scaled
the face: on a face with fuller or thinner lips than the source's they sit on the skin above or below the
lip, or inside its red, and nothing else measures it. The skin says where the lip is: seen from the side,
each lip bulges forward between the mouth's line and the skin above (the philtrum) or below it (the chin's
groove), and its outline (the vermilion border) lies beyond that bulge by a share of its height that
differs little between faces. So in each outer lip point's column of the front-view depth buffer
(:mod:`.front_depth`), the lip's front-most place is found within ``REACH`` of the mouth's width from the
mouth's line (through the corners and the inner lips' middle); the outline is ``OUTLINE`` times as far from
the line, and a point further than ``TOLERANCE`` of the mouth's width from it is doubtful. A column whose
front-most place is at the window's end (the skin keeps rising towards the nose: no bulge) says nothing.

``OUTLINE`` is the ratio of the true points' height above the line to the bulge's, measured on the two
faces whose lip points are known, ICT's (its kit landmarks) and the MediaPipe canonical face (its vertices
0, 37, 267 upper, 17, 84, 314 lower): upper lip beside the middle 0.99-1.02, upper middle 1.19 (MediaPipe's
philtrum rises to the nose with no bulge), lower 1.32-1.47. The tolerance covers that spread (at most
0.022 of the mouth's width) about twice over; a lip point moved 1 cm (0.22 of ICT's mouth width) is far
outside it. On ``bench perfect-sync``'s MediaPipe-warped heads the true points lie within 0.011 of the
outline, except the 1.5-times warp's upper lip (up to 0.046: its lip bulges higher than a face's): there the
margin is thin, and a proposed upper lip point on its true place is named (0.051).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.offline.perfect_sync.front_depth import depth_buffer

#: outer lip point -> the outline's height over the lip's bulge's, from the mouth's line (see the module doc)
OUTLINE = {"lip_upper": 1.2, "lip_upper_L": 1.0, "lip_upper_R": 1.0,
           "lip_lower": 1.4, "lip_lower_L": 1.4, "lip_lower_R": 1.4}
REACH = 0.35  # the lip's bulge is sought within this share of the mouth's width from its line
TOLERANCE = 0.05  # a point further than this share of the mouth's width from the outline is doubtful
PIXELS = 160  # pixels across the mouth's width
NEED = ("mouth_corner_L", "mouth_corner_R", "lip_upper_inner", "lip_lower_inner")


def outline_heights(names: Sequence[str], places: np.ndarray, local: np.ndarray,
                    triangles: np.ndarray) -> dict:
    """{outer lip point: (its height over the mouth's line, the outline's there)}, both in mouth widths, for
    the points whose column shows a lip bulge; ``places`` (n, 3) the points in the face frame (``names``'
    order), ``local`` the mesh's vertices in it, ``triangles`` the skin's."""
    names = tuple(names)
    if not all(n in names for n in NEED):
        return {}
    p = {n: np.asarray(places[names.index(n)], np.float64) for n in NEED}
    right, left = p["mouth_corner_R"], p["mouth_corner_L"]
    width = float(left[0] - right[0])
    if width <= 0:
        return {}
    middle = 0.5 * (p["lip_upper_inner"] + p["lip_lower_inner"])

    def line(x: float) -> float:  # the mouth's line through its corners and its inner lips' middle
        return float(np.interp(x, [right[0], middle[0], left[0]], [right[1], middle[1], left[1]]))

    h = width / PIXELS
    out = {}
    for name, ratio in OUTLINE.items():
        if name not in names:
            continue
        x, y = places[names.index(name)][:2]
        base = line(x)
        sign = 1.0 if name.startswith("lip_upper") else -1.0
        rows = int(REACH * width / h)
        y0 = base if sign > 0 else base - REACH * width
        column = depth_buffer(local, triangles, float(x), y0, h, (rows + 1, 1))[:, 0]
        if sign < 0:
            column = column[::-1]  # from the line outwards
        finite = np.isfinite(column)
        if finite.sum() < 3:
            continue
        k = int(np.argmax(np.where(finite, column, -np.inf)))
        if k >= rows - 1:
            continue  # the skin rises to the window's end: no bulge in this column
        out[name] = (sign * (y - base) / width, ratio * k * h / width)
    return out


def outline_doubts(names: Sequence[str], places: np.ndarray, local: np.ndarray, triangles: np.ndarray) -> list[dict]:
    """A doubt {"points": [name], "why"} for each outer lip point further than ``TOLERANCE`` of the mouth's
    width from the lip's outline in its column (see :func:`outline_heights`)."""
    out = []
    for name, (at, outline) in outline_heights(names, places, local, triangles).items():
        if abs(at - outline) > TOLERANCE:
            where = "above" if (at > outline) == name.startswith("lip_upper") else "below"
            out.append({"points": [name], "why": f"off the lip's outline: {abs(at - outline):.2f} of the mouth's "
                                                 f"width {where} it (the point {at:.2f} from the mouth's line, the "
                                                 f"outline {outline:.2f} by the lip's bulge in the skin; > "
                                                 f"{TOLERANCE}): the lip is fuller or thinner than the source's; "
                                                 "put it on the lip's edge"})
    return out
