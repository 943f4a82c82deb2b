"""Does a closed lid cover the eye over its whole length? Measured from the front, pixel by pixel.

The mid-lid gap (:func:`~.evaluate.mid_lid_gap`) is one number at one place: a blink whose lids meet there can
still leave the eyeball, its tear film or the dark socket showing through a slit elsewhere along the lid, or
fold the lid's skin so that its back faces show (the dark pinholes a viewer sees on a cloned ICT blink). So
the eye's opening at rest, seen from the front (:func:`~.eye_openings.eye_opening`), is the region a closed
lid must cover; the shaped face is drawn into an id buffer over a window about it (every triangle of the face
mesh, looking along −z of the face frame), and a pixel *shows the eye* when its front-most surface is

* a piece of the eye: a piece that is not skin and that, at rest, is seen mostly through the opening or not at
  all (the eyeball, its tear film and shadow mesh; not the lashes, which are seen mostly outside it),
  anywhere in the window (what pokes through the closed lid may lie above the opening's rest line),
* within the opening, skin seen from behind (a fold: its triangle faces away from the viewer, the skin's front
  faces seen at rest telling which winding faces the viewer), or
* within the opening, nothing (a hole through the head).

The figure is the count of such pixels as a fraction of the opening's, and how many separate places
(connected runs of pixels) they make; see :data:`ALLOWED`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.perfect_sync.eye_openings import EYE_POINTS, eye_opening
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.front_depth import front_buffers

#: a closed blink may leave this fraction of its rest opening's area showing the eye: about twice the most a
#: true blink shows (ICT's shadow mesh lies along the closed lid line, between the lashes: 2.7 % of the opening
#: on ICT and on its variants warped towards other faces)
ALLOWED = 0.05
EYE_PIECE = 0.5  # a piece seen at rest more than this fraction of its visible pixels inside the opening is the eye's
SUB = 3  # measure pixels per side of an opening pixel (an opening pixel: 1/60 inner-eye distance)
BLINKS = (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R"))


def id_buffer(local: np.ndarray, triangles: np.ndarray, x0: float, y0: float, h: float,
              shape: tuple[int, int]) -> np.ndarray:
    """(rows, cols) index into ``triangles`` of the front-most triangle (largest z of ``local`` (n, 3), face
    frame) at each pixel centre (size ``h``, first centre (x0, y0), rows up), −1 where none is drawn."""
    return front_buffers(local, triangles, x0, y0, h, shape)[1]


def _facing(local: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m,) sign of each triangle's normal along +z (towards the viewer) in the face frame."""
    p = local[triangles]
    return np.sign(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2])


class EyeCover:
    """The rest eye openings of a face and its pieces, to measure shapes against (see the module doc)."""

    def __init__(self, vertices: np.ndarray, face: Face, points: ControlPoints) -> None:
        self.face = face
        v = np.asarray(vertices, np.float64)
        self.local = face.to_frame(v)
        self.triangles = np.asarray(face.triangles, np.int64)
        skin = np.zeros(len(v), bool)
        skin[face.skin] = True
        self.skin_t = skin[self.triangles].all(axis=1)
        _, labels = components(len(v), self.triangles)
        self.piece = labels[self.triangles[:, 0]]
        self.eyes: dict = {}
        if not all(f"eye_inner_{s}" in points.names for s in "LR"):
            return
        es = float(np.linalg.norm(self.local[points.vertex("eye_inner_L"), :2]
                                  - self.local[points.vertex("eye_inner_R"), :2]))
        if es <= 0:
            return
        skin_tris = self.triangles[self.skin_t]
        front = _facing(self.local, self.triangles)
        for side in ("L", "R"):
            need = [f"{n}_{side}" for n in EYE_POINTS]
            if not all(n in points.names for n in need):
                continue
            centre = self.local[[points.vertex(n) for n in need], :2].mean(0)
            found = eye_opening(self.local, skin_tris, centre, es)
            if found is None:
                continue
            x0, y0, h = found["grid"]  # each of its pixels split SUB x SUB: a slit is a fraction of a pixel wide
            x0, y0, h = x0 - h * (SUB - 1) / (2 * SUB), y0 - h * (SUB - 1) / (2 * SUB), h / SUB
            opening = np.repeat(np.repeat(found["open"], SUB, axis=0), SUB, axis=1)
            ids = id_buffer(self.local, self.triangles, x0, y0, h, opening.shape)
            drawn = ids >= 0
            # the skin's winding that faces the viewer: the majority over the skin seen at rest
            seen_skin = ids[drawn & ~opening]
            seen_skin = seen_skin[self.skin_t[seen_skin]]
            viewer = float(np.sign(front[seen_skin].sum())) if len(seen_skin) else 1.0
            # the eye's pieces: not skin, and at rest seen mostly through the opening or not at all (the eyeball
            # behind its tear film); a piece seen mostly outside it (a lash) is no part of what the lid covers
            pieces = self.piece[ids[drawn]]
            inside = opening[drawn]
            outside = [p for p in np.unique(pieces) if inside[pieces == p].mean() <= EYE_PIECE]
            eye_pieces = np.setdiff1d(np.unique(self.piece[~self.skin_t]), outside)
            self.eyes[side] = {"grid": (x0, y0, h), "open": opening, "viewer": viewer,
                               "eye_pieces": eye_pieces}

    def showing(self, side: str, delta: np.ndarray) -> dict | None:
        """{"fraction": of the rest opening's pixels that show the eye with the deltas ``delta`` (n, 3, world)
        applied, "places": how many separate runs of such pixels, "pixels": their count, "eye", "back", "none":
        pixels by what shows} for the eye ``side``, or None when it has no eye-like opening."""
        eye = self.eyes.get(side)
        if eye is None:
            return None
        x0, y0, h = eye["grid"]
        opening = eye["open"]
        shaped = self.local + np.asarray(delta, np.float64) @ self.face.frame.T
        ids = id_buffer(shaped, self.triangles, x0, y0, h, opening.shape)
        drawn = ids >= 0
        safe = np.where(drawn, ids, 0)
        facing = _facing(shaped, self.triangles)[safe]
        is_eye = drawn & np.isin(self.piece[safe], eye["eye_pieces"]) & ~self.skin_t[safe]
        back = drawn & self.skin_t[safe] & (facing * eye["viewer"] < 0)
        none = ~drawn
        # the eye's pieces anywhere in the window (a tear film poking through the lid above the opening's rest
        # line), the lid's back or nothing within the opening (the window's skin has silhouettes of its own)
        bad = is_eye | (opening & (back | none))
        _, places = ndimage.label(bad)
        n = int(opening.sum())
        return {"fraction": float(bad.sum() / max(n, 1)), "places": int(places), "pixels": int(bad.sum()),
                "eye": int(is_eye.sum()), "back": int((opening & back).sum()),
                "none": int((opening & none).sum()), "opening_pixels": n}


def blink_cover(cover: EyeCover, names: tuple[str, ...] | list[str], dense: np.ndarray) -> dict:
    """{blink key: :meth:`EyeCover.showing`} of each blink among ``names`` (dense deltas ``dense`` (k, n, 3))."""
    out = {}
    for key, side in BLINKS:
        if key in names:
            got = cover.showing(side, dense[list(names).index(key)])
            if got is not None:
                out[key] = got
    return out


def open_blinks(cover: dict, allowed: float = ALLOWED) -> list[dict]:
    """[{"shape", "showing", "why"}] of each blink in ``cover`` (:func:`blink_cover`) that leaves more than
    ``allowed`` of its eye's opening showing."""
    out = []
    for key, c in cover.items():
        if c["fraction"] > allowed:
            what = ", ".join(f"{n} {label}" for n, label in ((c["eye"], "the eye's pieces"), (c["back"], "the lid's "
                             "back faces"), (c["none"], "nothing (a hole)")) if n)
            out.append({"shape": key, "showing": round(c["fraction"], 4),
                        "why": f"the closed lid leaves {100 * c['fraction']:.1f} % of the eye's opening showing at "
                               f"{c['places']} place(s) (pixels seen: {what})"})
    return out


def cover_against_truth(truth: Character, cloned: Character, face: Face, points: ControlPoints) -> dict:
    """{blink key: {"true", "cloned": fraction of the eye's opening showing}} of a character whose true blinks are
    known (``cloned`` is ``truth``'s mesh with the cloned shapes after its own; ``points`` a known set, not the
    proposal, so that the measure does not depend on what it measures)."""
    cover = EyeCover(truth.vertices, face, points)
    by = {canonical(n): s for s, n in enumerate(truth.shape_names)}
    keys = [key for key, _ in BLINKS if key in by]
    true = blink_cover(cover, keys, truth.dense_deltas()[[by[k] for k in keys]]) if keys else {}
    mine = [canonical(n) for n in cloned.shape_names[truth.n_shapes:]]
    got = blink_cover(cover, mine, cloned.dense_deltas()[truth.n_shapes:])
    return {k: {"true": round(true[k]["fraction"], 4), "cloned": round(got[k]["fraction"], 4),
                "cloned_places": got[k]["places"]} for k in true if k in got}
