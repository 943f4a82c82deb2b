"""Proposed control-point correspondences on a character's face, their doubt report, the landmarks file.

The source's control points (an elastic table's ``control_positions``, the
ICT head's 47) are fitted to the target's skin coarsely and non-rigidly:

1. placed in the target's face frame (:mod:`.face`) with the nose tips
   together;
2. a scale and translation, with no sideways shift (both faces are
   symmetric), by ICP against the target's forward-facing skin, from a few
   starting scales, keeping the one with the smallest residual (relative to
   the scale);
   then a scale per axis (within a third of the uniform one);
3. a few non-rigid steps: each point moves halfway to its nearest skin
   vertex by the Gaussian-smoothed offsets of its neighbours, so the set
   bends to the target's proportions without collapsing;
4. the eyes' and the mouth's points put where their openings are (:mod:`.eye_openings`, :mod:`.mouth_slit`)
   and the points between them (cheekbones, cheeks) moved as they moved (:mod:`.feature_span`);
5. each point takes its nearest free skin vertex; ``nose_tip`` the face's
   detected nose tip unless the fit's lies within 0.3 FAPU of it; the inner lips the nearest skin vertex facing down
   (upper) or up (lower), the mouth's inner corners where the lips touch
   (:mod:`.lip_contact`), then put in order (:func:`fix_inner_lips`).

On a decal face (its eyes or mouth drawn on pieces in front of a skin with no
openings, :func:`~.pieces.find_pieces`: Godette's box head) the skin has no
vertex where the features are, so the points are put on the features instead
(:func:`_decal_proposal`), where the landmark field moving them places them.

Doubts (:func:`doubts`): a point that does not fit its neighbours by the source's
layout (:mod:`.local_fit`) or breaks the order of a face's features
(:mod:`.layout_checks`), a sided point on the wrong side of the symmetry
plane or far from its mirrored partner (asymmetric), a point off the skin or
facing away (off the surface), the inner lips in the wrong order, on one
vertex, or with no opening between them (lips not separated), a closed
mouth's inner corners not where its lips touch (:func:`~.lip_contact.corner_doubts`),
an outer lip point off the lips' outline, which the lip's bulge in the skin gives (:mod:`.lip_outline`),
a hole in the skin among the points that is not an eye or the mouth
(:func:`holes`). The landmarks
file is the control-point file of :mod:`facepuppet.offline.elastic.control_points`;
:func:`read_landmarks` refuses unknown and missing names.
"""

from __future__ import annotations

import os
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.elastic.control_points import ControlPoints, read_control_points
from facepuppet.offline.elastic.lip_line import CORNERS, LOWER, UPPER, boundary_loops, fix_inner_lips, mouth_slit
from facepuppet.offline.perfect_sync.eye_openings import eye_points
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.feature_span import MOUTH_CORNERS as CORNERS_OF_MOUTH
from facepuppet.offline.perfect_sync.feature_span import between_features
from facepuppet.offline.perfect_sync.landmark_field import EYE_NAMES, MOUTH_NAMES, feature_places
from facepuppet.offline.perfect_sync.layout_checks import by_feature, decal_doubts, order_doubts
from facepuppet.offline.perfect_sync.lip_contact import corner_doubts, inner_corners
from facepuppet.offline.perfect_sync.lip_outline import outline_doubts
from facepuppet.offline.perfect_sync.local_fit import poor_fits
from facepuppet.offline.perfect_sync.mouth_slit import is_mouth_point, mouth_places
from facepuppet.offline.perfect_sync.pieces import Pieces

START_SCALES = (0.6, 0.8, 1.0, 1.25, 1.6)
NOSE_SNAP = 0.3  # the fitted nose tip is kept within this many FAPU of the detected one
AXIS_RANGE = 1.33  # each axis's scale within this factor of the uniform fit's
ICP_STEPS = 20
BEND_STEPS = 6
ASYMMETRY = 0.25  # a mirrored pair further apart than this many FAPU (inner-eye distances) is doubtful
OFF_SURFACE = 0.5  # a fitted point this many FAPU from the skin vertex it took is doubtful
MIN_CANDIDATES = 120  # fewer forward-facing skin vertices than this: every skin vertex is a candidate


def _front_skin(vertices: np.ndarray, face: Face) -> np.ndarray:
    normals = vertex_normals(vertices.astype(np.float32), face.triangles.astype(np.uint32)).astype(np.float64)
    z = normals[face.skin] @ face.frame[2]
    front = face.skin[z > 0.2]
    return front if len(front) >= MIN_CANDIDATES else face.skin  # a low-poly face: all of its skin


def _fit_scale(src: np.ndarray, tgt: np.ndarray, tree: cKDTree, scale: float) -> tuple[float, np.ndarray, float]:
    """ICP for p = s src + t (t_x = 0) against ``tgt``; returns (s, t, residual / s)."""
    s, t = scale, np.zeros(3)
    for _ in range(ICP_STEPS):
        _, j = tree.query(s * src + t)
        q = tgt[j]
        sm, qm = src.mean(0), q.mean(0)
        a, b = src - sm, q - qm
        s_new = float((a * b).sum() / max((a * a).sum(), 1e-18))
        if s_new <= 0:
            break
        s = s_new
        t = qm - s * sm
        t[0] = 0.0
    d, _ = tree.query(s * src + t)
    return s, t, float(np.sqrt(np.mean(d**2))) / s


def _fit_axes(src: np.ndarray, tgt: np.ndarray, tree: cKDTree, scale: float, t: np.ndarray) -> tuple[np.ndarray,
                                                                                                       np.ndarray]:
    """ICP for p = diag(s) src + t from the uniform fit: a scale per axis of the face frame, each kept within
    ``AXIS_RANGE`` of the uniform one (a face wider than tall, a long jaw); returns (s (3,), t)."""
    s = np.full(3, scale)
    for _ in range(ICP_STEPS):
        _, j = tree.query(src * s + t)
        q = tgt[j]
        sm, qm = src.mean(0), q.mean(0)
        a, b = src - sm, q - qm
        s = np.clip((a * b).sum(0) / np.maximum((a * a).sum(0), 1e-18), scale / AXIS_RANGE, scale * AXIS_RANGE)
        t = qm - s * sm
        t[0] = 0.0
    return s, t


def fit_points(source_positions: np.ndarray, source_names: Sequence[str], vertices: np.ndarray,
               face: Face) -> tuple[np.ndarray, np.ndarray]:
    """The source control points fitted onto the target's skin, (n_c, 3) in target world units, and the
    forward-facing skin vertices they may take (int64)."""
    names = tuple(source_names)
    src = np.asarray(source_positions, np.float64)
    src = src - src[names.index("nose_tip")]  # source stored +Y up, +Z forward (the project's convention)
    v = np.asarray(vertices, np.float64)
    cand = _front_skin(v, face)
    tgt = face.to_frame(v[cand])
    tree = cKDTree(tgt)
    base = face.width / max(1.9 * float(np.ptp(src[:, 0])), 1e-18)  # the ICT head is ~1.9 times its points wide
    best = min((_fit_scale(src, tgt, tree, base * k) for k in START_SCALES), key=lambda r: r[2])
    s, t = _fit_axes(src, tgt, tree, best[0], best[1])
    p = s * src + t
    es = s[0] * float(np.linalg.norm(src[names.index("eye_inner_L")] - src[names.index("eye_inner_R")]))
    sigma = 1.5 * es
    w = np.exp(-((p[:, None] - p[None]) ** 2).sum(-1) / (2 * sigma**2))
    w /= w.sum(1, keepdims=True)
    for _ in range(BEND_STEPS):  # coarse non-rigid: smoothed offsets to the nearest skin vertex
        _, j = tree.query(p)
        p = p + 0.5 * w @ (tgt[j] - p)
    world = (p + face.origin) @ face.frame  # back out of the face frame
    return world, cand


def _decal_proposal(names: tuple, source_positions: np.ndarray, vertices: np.ndarray, face: Face,
                    pieces: Pieces) -> tuple[ControlPoints, np.ndarray] | None:
    """On a decal face (:func:`~.pieces.find_pieces` found its eyes or mouth drawn on pieces in front of a skin
    with no openings), the points where the features are: each at the place :func:`~.landmark_field.feature_places`
    gives it (eye points by the eye's box of corners and lids, mouth points by the mouth's corners and line, the
    others by the affine map these define), on the nearest vertex (across the face's front) of what draws it:
    the eye's pieces for the eye's corners and lids, the mouth's pieces for the lips (the upper lip's above the
    mouth's line, the lower's below it), the pieces on the skin or the skin for the brows, the detected nose tip,
    the forward-facing skin for the rest. None when the features place fewer than 3 points."""
    pos, _, placed = feature_places(pieces, source_positions, names)
    if placed.sum() < 3:
        return None
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    weld = face.weld if face.weld is not None else np.arange(len(v))
    first = lambda m: np.unique(weld[np.asarray(m, np.int64)])  # noqa: E731  one vertex per position
    normals = vertex_normals(v.astype(np.float32), face.triangles.astype(np.uint32)).astype(np.float64)
    front = face.skin[normals[face.skin] @ face.frame[2] > 0.2]
    skin = first(front if len(front) >= len(names) else face.skin)
    drawn = first(pieces.on_skin) if len(pieces.on_skin) else np.zeros(0, np.int64)
    mouth = first(pieces.mouth[0]) if pieces.mouth is not None else None
    taken: set = {int(face.nose_tip)}
    chosen = []
    for i, name in enumerate(names):
        side = name[-1] if name.endswith(("_L", "_R")) else None
        if name == "nose_tip":
            chosen.append(int(face.nose_tip))
            continue
        if side in pieces.eyes and any(name == f"{e}_{side}" for e in EYE_NAMES):
            cand = first(pieces.eyes[side][0])
        elif name.startswith("brow"):
            cand = np.concatenate([drawn, skin])
        elif mouth is not None and any(name == p or name.startswith(p + "_") for p in MOUTH_NAMES):
            line = np.polyval(pieces.mouth[2], local[mouth, 0])
            above = local[mouth, 1] > line
            cand = mouth[above] if name.startswith("lip_upper") else mouth[~above] if name.startswith(
                "lip_lower") else mouth
        else:
            cand = skin
        cand = np.array([c for c in cand if int(c) not in taken], np.int64)
        if not len(cand):
            cand = np.array([c for c in skin if int(c) not in taken], np.int64)
        pick = int(cand[np.argmin(np.linalg.norm(local[cand, :2] - pos[i], axis=1))])
        taken.add(pick)
        chosen.append(pick)
    fitted = np.column_stack([pos, local[chosen, 2]])
    fitted[names.index("nose_tip")] = local[face.nose_tip]
    return ControlPoints(names, np.array(chosen, np.int64)), (fitted + face.origin) @ face.frame


def propose(source_positions: np.ndarray, source_names: Sequence[str], vertices: np.ndarray,
            face: Face, pieces: Pieces | None = None) -> tuple[ControlPoints, np.ndarray]:
    """Proposed target control points (source names, source order) and the fitted positions (n_c, 3).

    ``pieces`` (:func:`~.pieces.find_pieces`), when they hold decal features, place the points on them
    (:func:`_decal_proposal`) rather than by fitting the source's points to the skin."""
    names = tuple(source_names)
    if pieces is not None and (pieces.eyes or pieces.mouth is not None):
        decal = _decal_proposal(names, source_positions, vertices, face, pieces)
        if decal is not None:
            return decal
    fitted, cand = fit_points(source_positions, names, vertices, face)
    v = np.asarray(vertices, np.float64)
    tree = cKDTree(v[cand])
    # the nose tip: the fit's nearest vertex when it lies near the face's detected tip, else the detected one
    i_nose = names.index("nose_tip")
    es = float(np.linalg.norm(fitted[names.index("eye_inner_L")] - fitted[names.index("eye_inner_R")]))
    nose = int(cand[tree.query(fitted[i_nose])[1]])
    if np.linalg.norm(v[nose] - v[face.nose_tip]) > NOSE_SNAP * es:
        nose = face.nose_tip
    # the eye's points on its lid margins and corners where its opening is found (the coarse fit misses them
    # by millimetres on a head of other proportions, and the blinks lean on them)
    on_lids = eye_points(source_positions, names, fitted, v, face, skin_triangles(face), cand)
    fitted = np.array(fitted)
    mouth = mouth_places(source_positions, names, fitted, v, face, skin_triangles(face))
    found = {**{n: fitted[names.index(n)] for n in CORNERS_OF_MOUTH if mouth and n in names}, **mouth,
             **{n: v[k] for n, k in on_lids.items()}}  # a corner the slit agrees with stays the fit's
    span = between_features(source_positions, names, fitted, found, face,
                            {*(n for n in names if is_mouth_point(n) or n.startswith(("nose", "nostril")))})
    for name, place in {**mouth, **span}.items():
        fitted[names.index(name)] = place  # about the lips' meeting line; between the eyes and the mouth
    for name, vertex in on_lids.items():
        fitted[names.index(name)] = v[vertex]
    taken = {nose, *on_lids.values()}
    chosen = []
    for name, point in zip(names, fitted):
        if name == "nose_tip":
            chosen.append(nose)
            continue
        if name in on_lids:
            chosen.append(on_lids[name])
            continue
        _, order = tree.query(point, k=min(len(cand), len(names) + 1))
        pick = next((int(cand[i]) for i in np.atleast_1d(order) if int(cand[i]) not in taken), None)
        if pick is None:
            raise InputFileError(f"proposal: the skin's {len(cand)} forward-facing vertices cannot hold "
                                 f"{len(names)} control points")
        taken.add(pick)
        chosen.append(pick)
    chosen = _inner_lips(names, chosen, fitted, v, face)
    chosen, _ = inner_corners(names, chosen, v, face, skin_triangles(face))  # under the upper lip, not beside it
    points = ControlPoints(names, np.array(chosen, np.int64))
    fixed = fix_inner_lips(points, v, skin_triangles(face), cand)
    if len(np.unique(fixed.vertices)) == len(names):  # a lip line too small for its points: keep the fit's
        points = fixed
    return points, fitted


def _inner_lips(names: tuple, chosen: list, fitted: np.ndarray, v: np.ndarray, face: Face) -> list:
    """The inner-lip points on the skin vertex nearest their fitted place whose normal faces down (upper lip)
    or up (lower lip): where the lips touch, the two lips' vertices lie a hair apart and only their normals
    tell them apart (ICT's inner lips face within 15 degrees of straight down / up, and not forward)."""
    if UPPER not in names or LOWER not in names:
        return chosen
    normals = vertex_normals(v.astype(np.float32), skin_triangles(face).astype(np.uint32)).astype(np.float64)
    up = normals[face.skin] @ face.frame[1]
    out = list(chosen)
    taken = set(out)
    for name, sign in ((UPPER, -1.0), (LOWER, 1.0)):
        i = names.index(name)
        cand = face.skin[sign * up > 0.5]
        cand = cand[[int(c) not in taken or int(c) == out[i] for c in cand]]
        if len(cand):
            pick = int(cand[np.argmin(np.linalg.norm(v[cand] - fitted[i], axis=1))])
            taken.discard(out[i])
            out[i] = pick
            taken.add(pick)
    return out


def skin_triangles(face: Face) -> np.ndarray:
    """The face mesh's triangles on the skin, (q', 3) int64."""
    return face.triangles[np.isin(face.triangles, face.skin).all(axis=1)]


def _partner(name: str) -> str | None:
    if name.endswith("_L"):
        return name[:-2] + "_R"
    if name.endswith("_R"):
        return name[:-2] + "_L"
    return None


def fapu_of(points: ControlPoints, vertices: np.ndarray) -> float:
    v = np.asarray(vertices, np.float64)
    return float(np.linalg.norm(v[points.vertex("eye_inner_L")] - v[points.vertex("eye_inner_R")]))


def doubts(points: ControlPoints, vertices: np.ndarray, face: Face,
           fitted: np.ndarray | None = None, pieces: Pieces | None = None, *,
           source_positions: np.ndarray | None = None) -> list[dict]:
    """Doubtful points: a list of {"points": [names], "why": text} (empty when none); see the module doc.

    With the source's control points (``source_positions`` (n_c, 3), in ``points``' order), also the points
    breaking the order every face keeps (:mod:`.layout_checks`: the lids under the brow, the mouth's corners at
    its ends) and, on a face whose points were fitted (not a decal face's, placed by what is drawn at its own
    proportions), those whose place does not fit their neighbours by the source's layout (:mod:`.local_fit`,
    one doubt per feature) and eyes or a mouth far from the source's proportions.

    With decal ``pieces`` (:func:`~.pieces.find_pieces`), the surface is the skin and what is drawn on it (the
    decal eyes, mouth and the pieces lying on the skin), and inner lips on a decal mouth need not have an opening
    between them (the drawn mouth opens along its line, :func:`~.landmark_field.feature_field`)."""
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v[points.vertices])
    es = max(fapu_of(points, v), 1e-12)
    out = []
    weld = face.weld if face.weld is not None else np.arange(len(v))
    skin = set(int(i) for i in face.skin)
    decal_mouth = set()
    if pieces is not None and (pieces.eyes or pieces.mouth is not None):
        skin |= set(int(i) for i in weld[pieces.feature_vertices]) | set(int(i) for i in weld[pieces.on_skin])
        if pieces.mouth is not None:
            decal_mouth = set(int(i) for i in weld[pieces.mouth[0]])
    skin |= {int(i) for i in np.flatnonzero(np.isin(weld, list(skin)))}  # every copy of a surface vertex
    for name, vertex, p in zip(points.names, points.vertices, local):
        side = 1.0 if name.endswith("_L") else -1.0 if name.endswith("_R") else 0.0
        if side and side * p[0] < 0:
            out.append({"points": [name], "why": f"on the wrong side of the face ({'left' if side > 0 else 'right'} "
                                                 f"point at x = {p[0]:.3g} in the face frame)"})
        if int(vertex) not in skin:
            out.append({"points": [name], "why": f"off the surface: vertex {int(vertex)} is not on the face's skin"})
    for i, name in enumerate(points.names):
        other = _partner(name)
        if name.endswith("_L") and other in points.names:
            j = points.index(other)
            mirrored = local[j] * np.array([-1.0, 1.0, 1.0])
            gap = float(np.linalg.norm(local[i] - mirrored)) / es
            if gap > ASYMMETRY:
                out.append({"points": [name, other],
                            "why": f"asymmetric: {gap:.2f} FAPU from each other's mirror image (> {ASYMMETRY})"})
    if fitted is not None:
        for name, vertex, f in zip(points.names, points.vertices, np.asarray(fitted, np.float64)):
            if name in (UPPER, LOWER, *CORNERS):
                continue  # put on the lip line by fix_inner_lips, not by the fit
            d = float(np.linalg.norm(v[vertex] - f)) / es
            if d > OFF_SURFACE:
                out.append({"points": [name], "why": f"off the surface: the fitted point is {d:.2f} FAPU from the "
                                                     f"nearest free skin vertex (> {OFF_SURFACE})"})
    out += holes(points, v, face)
    if source_positions is not None:
        src = np.asarray(source_positions, np.float64)[:, :2]  # the source is stored +Y up, +X its left
        decal = pieces is not None and (bool(pieces.eyes) or pieces.mouth is not None)
        if not decal:  # decal points are placed by what is drawn, at its proportions, not fitted to the layout
            out += by_feature(poor_fits(src, local[:, :2], points.names), points.names)
            out += outline_doubts(points.names, local, face.to_frame(v), skin_triangles(face))
        out += order_doubts(src, local[:, :2], points.names, es, proportions=not decal)
        if decal:
            out += decal_doubts(local[:, :2], points.names, pieces.eyes, pieces.mouth)
    if UPPER in points.names and LOWER in points.names:
        up, low = points.vertex(UPPER), points.vertex(LOWER)
        if up == low or local[points.index(UPPER), 1] <= local[points.index(LOWER), 1]:
            out.append({"points": [UPPER, LOWER], "why": "lips not separated: the upper inner lip point is not "
                                                         "above the lower one"})
        else:
            corners = [n for n in ("mouth_corner_R", "mouth_corner_L") if n in points.names]
            width = np.ptp(v[[points.vertex(n) for n in corners]] @ face.frame[0]) if len(corners) == 2 else es
            joined = np.isin(skin_triangles(face), [up, low]).sum(axis=1) == 2
            on_decal = int(weld[up]) in decal_mouth and int(weld[low]) in decal_mouth
            slit = None if on_decal else mouth_slit(v, skin_triangles(face), 0.5 * (v[up] + v[low]), 1.5 * width)
            if not on_decal and joined.any() and slit is None:
                out.append({"points": [UPPER, LOWER], "why": "lips not separated: the inner lip points share a "
                                                             "triangle and no opening runs between the lips (a "
                                                             "closed mouth); jawOpen stretches them apart"})
            if not on_decal and not decal_mouth and slit is None:  # a closed mouth: its inner corners on the contact
                out += corner_doubts(points.names, points.vertices, v, face, skin_triangles(face))
    return out


def holes(points: ControlPoints, vertices: np.ndarray, face: Face) -> list[dict]:
    """Doubts for holes in the face: skin boundary loops within the control points' extent, smaller than half
    of it (a face mask's own border is not a hole), that are not an eye or the mouth opening (their centre
    more than an inner-eye distance from the eye corners' and the mouth corners' mid-points), each naming
    the control point nearest to it."""
    v = np.asarray(vertices, np.float64)
    es = max(fapu_of(points, v), 1e-12)
    local_points = face.to_frame(v[points.vertices])
    lo, hi = local_points.min(0), local_points.max(0)
    openings = []
    for a, b in (("eye_inner_L", "eye_outer_L"), ("eye_inner_R", "eye_outer_R"), ("mouth_corner_L", "mouth_corner_R")):
        if a in points.names and b in points.names:
            openings.append(0.5 * (v[points.vertex(a)] + v[points.vertex(b)]))
    out = []
    for loop in boundary_loops(len(v), skin_triangles(face)):
        centre = v[loop].mean(0)
        c = face.to_frame(centre)
        if np.any(c[:2] < lo[:2]) or np.any(c[:2] > hi[:2]) or c[2] < lo[2]:
            continue  # outside the face (the neck, the back of the head)
        if np.any(np.ptp(face.to_frame(v[loop])[:, :2], axis=0) > 0.5 * (hi - lo)[:2]):
            continue  # the border around a face mask (its centre is the face's), not a hole in it
        if any(np.linalg.norm(centre - o) < es for o in openings):
            continue
        near = points.names[int(np.argmin(np.linalg.norm(v[points.vertices] - centre, axis=1)))]
        out.append({"points": [near], "why": f"a hole in the face ({len(loop)} boundary vertices) near {near}: "
                                             "the skin must be closed there, or the clone tears it"})
    return out


def read_landmarks(path: str | os.PathLike, names: Sequence[str], n_vertices: int) -> ControlPoints:
    """A landmarks (control-point) file for the source's ``names``: ValueError naming unknown or missing points."""
    points = read_control_points(path, n_vertices)
    unknown = [n for n in points.names if n not in names]
    missing = [n for n in names if n not in points.names]
    if unknown or missing:
        parts = []
        if unknown:
            parts.append(f"unknown points {unknown}")
        if missing:
            parts.append(f"missing points {missing}")
        raise InputFileError(f"{path}: points: {'; '.join(parts)} (the source's control points are {list(names)})")
    return points.reorder(names)


def picture(path: str | os.PathLike, vertices: np.ndarray, face: Face, points: ControlPoints,
            doubtful: Sequence[str] = (), reasons: Sequence[dict] = (), size: int = 720) -> Path:
    """A front view of the face mesh (the skin grey, its other pieces blue-grey, shaded by facing) with the
    points: green, doubtful ones red in a red ring. With ``reasons`` (the doubts, :func:`doubts`) each doubt's
    points carry its number and a legend under the face says why, so the picture alone tells the user what to
    correct. Triangles are painted back to front by their hindmost corner, so a decal a hair in front of a
    large skin triangle shows over it."""
    v = face.to_frame(np.asarray(vertices, np.float64))
    tris = face.triangles
    used = np.unique(tris)
    lo, hi = v[used, :2].min(0), v[used, :2].max(0)
    scale = 0.9 * size / max(float((hi - lo).max()), 1e-12)

    mid = (lo + hi) / 2

    def xy(p):
        return size / 2 + (p[..., 0] - mid[0]) * scale, size / 2 - (p[..., 1] - mid[1]) * scale

    n = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-18)
    legend = [f"{k + 1}: {', '.join(d['points'])}: {d['why']}" for k, d in enumerate(reasons)]
    lines = [line for text in legend for line in textwrap.wrap(text, size // 6, subsequent_indent="   ")]
    img = Image.new("RGB", (size, size + 12 * len(lines) + (8 if lines else 0)), (24, 24, 28))
    draw = ImageDraw.Draw(img)
    depth = v[tris].min(1)[:, 2]
    on_skin = np.isin(tris, face.skin).all(1)
    for k in np.argsort(depth, kind="stable"):  # painter's order, back to front
        if n[k, 2] <= 0:
            continue
        shade = int(60 + 170 * n[k, 2])
        x, y = xy(v[tris[k]])
        fill = (shade, shade, shade) if on_skin[k] else (int(0.55 * shade), int(0.7 * shade), shade)
        draw.polygon(list(zip(x.tolist(), y.tolist())), fill=fill)
    bad = set(doubtful) | {n for d in reasons for n in d["points"]}
    number = {}
    for k, d in enumerate(reasons):
        for n in d["points"]:
            number.setdefault(n, []).append(str(k + 1))
    for name, vertex in zip(points.names, points.vertices):
        x, y = xy(v[vertex])
        colour = (230, 40, 40) if name in bad else (40, 200, 60)
        draw.ellipse([x - 4, y - 4, x + 4, y + 4], fill=colour)
        if name in bad:
            draw.ellipse([x - 9, y - 9, x + 9, y + 9], outline=colour, width=2)
        label = name + (f" [{','.join(number[name])}]" if name in number else "")
        draw.text((x + 9, y - 5), label, fill=colour)
    for i, line in enumerate(lines):
        draw.text((6, size + 4 + 12 * i), line, fill=(230, 120, 120))
    path = Path(path)
    img.save(path)
    return path
