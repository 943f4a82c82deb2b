"""The source's expressions cloned onto a character's face mesh and added as ARKit-named shapes.

The elastic cloning of Yano & Harada (2009) §5 (:func:`clone_model`) runs on
the face mesh only (:class:`~.face.Face`), so the body and every other mesh
cannot move; inside the face mesh the basis's fixed region (§4) holds the
back of the head, the pieces without control points below the lips follow
the jaw rigidly (:mod:`facepuppet.offline.elastic.rigid_parts`) and the
others (eyes, upper teeth) stay. Each cloned expression is evaluated once at
weight 1 and stored as a morph (dense → sparse deltas with normal deltas).

The source's shapes are folded into ARKit's 52: a shape whose name is an
ARKit name in any spelling (:func:`canonical`) directly; an unsided ARKit
shape the source splits (ICT's ``browInnerUp_L`` / ``_R``, ``cheekPuff_L`` /
``_R``) as the sum of its sides' parameters (the parameters are linear);
others (ICT's ``cheekRaiser``, ``PupilDilate``) are left out. The blinks'
upper lid points are then put onto the lower ones (:func:`close_lids`), and
the eye looks turn the eyeball pieces where the character has them
(:func:`eyeballs`) instead of leaving the eyes still under moving lids. On
a decal eye (drawn on pieces, :mod:`.pieces`) the looks move only the iris
and white inside its outline, taken from the character's own VRM look
expressions where it has them (:func:`decal_eye_looks`): those looks are
the character's lookAt, not cloned.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, arkit_index, canonical, split_side
from facepuppet.runtime.model.character import Character, sparse_deltas
from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.elastic.basis import DEFAULT_FIXED_RATIO, DEFAULT_K
from facepuppet.offline.elastic.clone import clone_model
from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.elastic.params import build_model
from facepuppet.offline.perfect_sync.drawn_eyes import decal_blink, decal_narrow, lid_fractions
from facepuppet.offline.perfect_sync.eye_caps import eye_caps, keep_on_ball
from facepuppet.offline.perfect_sync.eye_looks import decal_look_slide, look_expressions, look_keys
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.landmark_field import feature_field, lip_line_motion
from facepuppet.offline.perfect_sync.lid_seal import lid_margins, seal_blink
from facepuppet.offline.perfect_sync.on_skin import embed
from facepuppet.offline.perfect_sync.pieces import Pieces, find_pieces
from facepuppet.offline.perfect_sync.proposal import skin_triangles
from facepuppet.offline.perfect_sync.skin_clearance import keep_clearance
from facepuppet.offline.perfect_sync.triangles import nearest_triangles

CLOSED_GAP = 0.05  # a closed blink leaves this fraction of the rest gap between the lid points
# An eye look at weight 1 turns the eyeball this far (sideways, up or down). The source's shapes do not say
# (ICT's eyeLook shapes move the lids only: its eyes are turned by the app); a judgement, about the eye's
# comfortable range: 25 degrees sideways, 15 up and down (at 25 the ICT iris went under the upper lid).
EYE_LOOK_DEGREES = (25.0, 15.0)  # (about the up axis, about the across axis)
# The shapes that open the jaw (mouthClose closes the lips within jawOpen): on a decal mouth over a skin that
# does not move, the drawn mouth shows only the lips' motion relative to each other in these, not the jaw's
# translation (which would slide the mouth down its unmoving chin).
JAW_OPENINGS = ("jawOpen", "mouthClose")
# A lid passing over an eyeball keeps at most this fraction of its radius clear of it (at most its rest clearance:
# ICT's lid 0.26-0.44 cm over a 1.67 cm ball). The lid's triangles span up to 0.6 cm across the ball, whose surface
# bulges a chord's sagitta (0.03 cm) and its cornea's more between their corners: at 0.03 of the radius (0.05 cm)
# the ball came through the cloned ICT blink's closed lid (8 % of the eye's opening, :mod:`.lid_cover`).
EYE_CLEARANCE = 0.1
ROUND = 0.3  # an eyeball's vertices lie within this fraction of its radius from its least-squares sphere
MOUTH_CLEARANCE = 0.25  # outer skin pushed towards the teeth or gums keeps this fraction of its rest gap to them
# (shape, eye) -> (axis of the face frame, sign): right-hand rotations; +x is the character's left, so a
# turn about +y by + moves the front (+z) towards +x, one about +x by − moves it up.
EYE_TURNS = {
    ("eyeLookUpLeft", "L"): (0, -1.0), ("eyeLookUpRight", "R"): (0, -1.0),
    ("eyeLookDownLeft", "L"): (0, 1.0), ("eyeLookDownRight", "R"): (0, 1.0),
    ("eyeLookOutLeft", "L"): (1, 1.0), ("eyeLookInLeft", "L"): (1, -1.0),
    ("eyeLookOutRight", "R"): (1, -1.0), ("eyeLookInRight", "R"): (1, 1.0),
}


def fold_source(source: ElasticModel) -> tuple[tuple[str, ...], np.ndarray]:
    """(ARKit names the source can give, in ARKit's order; their parameters (n, n_c, 3) float32)."""
    params = source.arrays["params"].astype(np.float64)
    by_key: dict[str, int] = {}
    for s, name in enumerate(source.shape_names):
        by_key.setdefault(canonical(name), s)
    names, out = [], []
    for key in ARKIT_NAMES:
        _, side = split_side(key)
        if key in by_key:
            out.append(params[by_key[key]])
        elif side is None and key + "Left" in by_key and key + "Right" in by_key:
            out.append(params[by_key[key + "Left"]] + params[by_key[key + "Right"]])
        else:
            continue
        names.append(key)
    return tuple(names), np.asarray(out, np.float32).reshape(len(names), len(source.control_names), 3)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle`` radians about unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def eyeballs(vertices: np.ndarray, triangles: np.ndarray, points: ControlPoints) -> dict:
    """{"L"/"R": (vertex indices, centre (3,))} of the eyeball pieces found behind each eye's corners.

    An eyeball is a piece without control points that is close to a sphere (every vertex within 30 %
    of the radius from the least-squares sphere; ICT's sclera 8 %, its iris and cornea 14 %; on a head
    warped to other proportions, whose eyeballs the warp bends, up to 21 % and 29 %: missed, its lids had
    nothing to pass over and the eye showed through the closed lid), of radius
    0.2–0.8 inner-eye distances, at least a radius deep (not a cap like ICT's tear film), centred
    behind the eye's corners, between them across the eye and within half an inner-eye distance of
    their mid-point. A character whose eyes are flat decals or part of the skin has none, and its eye
    looks stay skin-only.
    """
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    need = ("eye_inner_L", "eye_outer_L", "eye_inner_R", "eye_outer_R")
    if not all(n in points.names for n in need):
        return {}
    es = float(np.linalg.norm(v[points.vertex("eye_inner_L")] - v[points.vertex("eye_inner_R")]))
    _, labels = components(len(v), t)
    handled = np.zeros(len(v), bool)
    handled[points.vertices] = True
    out: dict = {}
    for label in np.unique(labels[np.unique(t)]):
        members = np.flatnonzero(labels == label)
        if handled[members].any() or len(members) < 20:
            continue
        p = v[members]
        # sphere fit: |p|² = 2 c·p + (r² − |c|²), linear in c and the constant
        a = np.column_stack([2 * p, np.ones(len(p))])
        sol = np.linalg.lstsq(a, (p**2).sum(1), rcond=None)[0]
        centre = sol[:3]
        radius = float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))
        off_sphere = np.abs(np.linalg.norm(p - centre, axis=1) - radius).max()
        if not 0.2 * es < radius < 0.8 * es or off_sphere > ROUND * radius or np.ptp(p[:, 2]) < radius:
            continue  # not a ball: the wrong size, not round, or a thin cap (a tear film over the eye)
        for side in ("L", "R"):
            inner, outer = v[points.vertex(f"eye_inner_{side}")], v[points.vertex(f"eye_outer_{side}")]
            corners = 0.5 * (inner + outer)
            across = (outer - inner) / np.linalg.norm(outer - inner)
            behind = centre[2] < min(inner[2], outer[2])
            # the centre behind the corners' mid-point, between the corners across the eye
            if behind and np.linalg.norm(centre - corners) < 0.5 * es and abs((centre - corners) @ across) < 0.3 * es:
                prev = out.get(side)
                if prev is None:
                    out[side] = (members, centre, radius)
                else:  # sclera and iris: one eyeball, turned about the widest sphere's centre (the sclera's:
                    # the iris's cornea bulge pulls its fitted centre 0.09 cm forward on ICT, and turning about it
                    # pushes the eye through the tear film in front)
                    out[side] = (np.concatenate([prev[0], members]), prev[1] if prev[2] >= radius else centre,
                                 max(prev[2], radius))
    return {side: (members, centre) for side, (members, centre, _) in out.items()}


def close_lids(params: np.ndarray, names: tuple[str, ...], points: ControlPoints, vertices: np.ndarray,
               closed: float = CLOSED_GAP) -> np.ndarray:
    """``params`` (n_shapes, n_c, 3) with each blink's upper lid points brought onto the lower ones.

    The eq. 6 parameters are a least-squares compromise over the whole skin: on ICT they leave the lid
    points of eyeBlink half open (0.44 of the 0.85 cm gap; the true shape 0.08). A blink means the lids
    meet, so each upper lid point of ``eyeBlinkLeft`` / ``Right`` is put ``closed`` of its rest gap above
    its lower partner's displaced place (the lower lid keeps its cloned motion).
    """
    out = np.array(params, np.float64)
    v = np.asarray(vertices, np.float64)
    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        if key not in names:
            continue
        s = names.index(key)
        for part in ("inner", "outer"):
            a, b = f"lid_upper_{part}_{side}", f"lid_lower_{part}_{side}"
            if a not in points.names or b not in points.names:
                continue
            i, j = points.index(a), points.index(b)
            rest_up, rest_low = v[points.vertices[i]], v[points.vertices[j]]
            out[s, i] = rest_low + out[s, j] + closed * (rest_up - rest_low) - rest_up
    return out.astype(np.float32)


def naming_style(names: tuple[str, ...]) -> str:
    """The character's convention for ARKit names: "apple" (eyeBlinkLeft), "pascal" (EyeBlinkLeft) or
    "sided" (eyeBlink_L); "apple" when it has none."""
    styles = []
    for n in names:
        if arkit_index(n) is None:
            continue
        if n[:1].isupper():
            styles.append("pascal")
        elif n.endswith(("_L", "_R")):
            styles.append("sided")
        else:
            styles.append("apple")
    return max(set(styles), key=styles.count) if styles else "apple"


def spelled(key: str, style: str) -> str:
    """ARKit canonical ``key`` in the character's ``style``."""
    if style == "pascal":
        return key[:1].upper() + key[1:]
    if style == "sided":
        base, side = split_side(key)
        return base + "_" + side[0] if side else key
    return key


def clone_face(source: ElasticModel, character: Character, face: Face, points: ControlPoints, *,
               k: int = DEFAULT_K, fixed_ratio: float = DEFAULT_FIXED_RATIO,
               progress: Callable[[int, int, str], None] | None = None,
               info: dict | None = None, seal: bool = True) -> tuple[tuple[str, ...], np.ndarray]:
    """Cloned ARKit shapes on ``character``: (canonical names, dense deltas (n, n_vertices, 3) float32).

    ``seal``: the blinks' lids are brought together along the whole lid as measured on the character
    (:mod:`.lid_seal`); False leaves them as the clone and :func:`close_lids` made them (to measure what it does).
    ``info``, when given, receives {"pieces": ...}: how the pieces that are not skin were moved
    (:func:`carry_pieces`), and {"lid_seal": {blink: largest column correction (units)}}."""
    names, params = fold_source(source)
    weld = face.weld if face.weld is not None else np.arange(character.n_vertices)
    sub = np.unique(face.triangles)  # one vertex per position (the face's triangles are welded)
    local = np.full(character.n_vertices, -1, np.int64)
    local[sub] = np.arange(len(sub))
    local[face.mesh] = local[weld[face.mesh]]  # a seam's copies: their first copy's place in the solve
    sub_v = character.vertices[sub].astype(np.float64)
    sub_t = local[face.triangles]
    sub_points = ControlPoints(points.names, local[points.vertices])
    if (sub_points.vertices < 0).any():
        raise InputFileError("control points: every point must lie on the face mesh")
    folded = ElasticModel(arrays={**source.arrays, "params": params}, shape_names=names,
                          control_names=source.control_names, muscle_names=source.muscle_names,
                          units=source.units, metadata=dict(source.metadata))

    def build(tgt_points, cloned, shape_names):
        return build_model(sub_v, sub_t, tgt_points, cloned, shape_names, k=k, fixed_ratio=fixed_ratio,
                           units=character.units, with_muscles=False)[0]

    model = clone_model(folded, sub_points, sub_v, build, warped=True)
    params = close_lids(model.arrays["params"], names, sub_points, sub_v)
    eyes = eyeballs(sub_v, sub_t, sub_points)
    dense = np.zeros((len(names), character.n_vertices, 3), np.float32)
    up = np.tile([0, 0, 1.0], (len(sub_v), 1))
    skin_local = local[face.skin]
    lid_skin = {}  # the skin in front of each eyeball, which must pass over it, not through it
    for side, (members, centre) in eyes.items():
        reach = 1.6 * float(np.linalg.norm(sub_v[members] - centre, axis=1).max())
        rel = sub_v[skin_local] - centre
        lid_skin[side] = skin_local[(np.linalg.norm(rel, axis=1) < reach) & (rel @ face.frame[2] > 0)]
    inside = mouth_parts(sub_v, sub_t, skin_local, _mouth_ball(sub_points, sub_v), face.frame[2])
    sub_local = face.to_frame(sub_v)
    skin_sub = np.unique(skin_local)
    margins = lid_margins(sub_local, sub_t[np.isin(sub_t, skin_sub).all(axis=1)], skin_sub, sub_points) if seal else {}
    sealed = {}
    for s, name in enumerate(names):
        pos, _ = model.deform(params[s], sub_v.astype(np.float32), up)
        d = pos - sub_v
        largest = seal_blink(d, name, sub_local, skin_sub, margins, face.frame)
        if largest is not None:
            sealed[name] = round(largest, 4)
        for side, (members, centre) in eyes.items():
            turn = EYE_TURNS.get((name, side))
            if turn is not None:
                axis, sign = turn
                r = _rotation(face.frame[axis], sign * np.radians(EYE_LOOK_DEGREES[0 if axis == 1 else 1]))
                d[members] = (sub_v[members] - centre) @ r.T + centre - sub_v[members]
        for side, (members, centre) in eyes.items():
            d[lid_skin[side]] = clear_eyeball(sub_v, d, members, centre, lid_skin[side])
        if inside is not None:
            d[inside[1]] = clear_mouth_parts(sub_v, d, *inside)
        dense[s, face.mesh] = d[local[face.mesh]]
        if progress is not None:
            progress(s + 1, len(names), name)
    carried = carry_pieces(dense, source, names, fold_source(source)[1], character.vertices, face,
                 rigid=sub[model.arrays["rigid_labels"] >= 0],
                 eyeballs=np.concatenate([sub[m] for m, _ in eyes.values()] + [np.zeros(0, np.int64)]),
                 mouth=_mouth_ball(points, character.vertices),
                 looks=look_expressions(character.expressions, character.delta_offsets, character.delta_indices,
                                        character.delta_positions, character.n_vertices))
    # what lies on the eyeballs (tear films, shadow meshes) slides over them, as carried, never off through a lid
    balls = {side: (sub[members], centre) for side, (members, centre) in eyes.items()}
    caps = eye_caps(character.vertices, face.triangles, balls, face.frame[2])
    if keep_on_ball(dense, character.vertices, balls, caps) and face.weld is not None:
        copies = face.mesh[np.isin(face.weld[face.mesh], np.concatenate(list(caps.values())))]
        dense[:, copies] = dense[:, face.weld[copies]]
    if info is not None:
        info["pieces"] = carried
        info["lid_seal"] = sealed
    return names, dense


def clear_eyeball(rest: np.ndarray, d: np.ndarray, members: np.ndarray, centre: np.ndarray, near: np.ndarray,
                  margin: float = EYE_CLEARANCE) -> np.ndarray:
    """Displacements of the ``near`` skin vertices with none left inside the eyeball: a vertex whose shaped place
    lies closer to the eye's ``centre`` than the (shaped) eyeball's surface in its direction, plus the clearance it
    had at rest (at most ``margin`` of the eye's radius), is put back out along that direction. Vertices behind
    the eyeball's surface at rest (the socket) are left. Returns (len(near), 3)."""
    ball = rest[members] + d[members]
    rel = ball - centre
    radius = np.linalg.norm(rel, axis=1)
    tree = cKDTree(rel / radius[:, None])

    def surface(p):
        u = (p - centre) / np.maximum(np.linalg.norm(p - centre, axis=1, keepdims=True), 1e-12)
        _, j = tree.query(u, k=min(4, len(radius)))
        return u, radius[np.atleast_2d(j)].max(axis=1)  # the bulge (a cornea) among the nearest directions

    x = rest[near]
    _, at_rest = surface(x)
    clearance = np.linalg.norm(x - centre, axis=1) - at_rest
    p = x + d[near]
    u, now = surface(p)
    need = now + np.minimum(clearance, margin * radius.max())
    inside = (clearance > 0) & (np.linalg.norm(p - centre, axis=1) < need)
    out = np.array(d[near])
    out[inside] = centre + u[inside] * need[inside, None] - x[inside]
    return out


def mouth_parts(vertices: np.ndarray, triangles: np.ndarray, skin: np.ndarray, mouth: tuple | None,
                forward: np.ndarray) -> tuple | None:
    """The pieces inside the mouth (teeth, gums, tongue: pieces centred within the ``mouth`` ball (centre,
    radius)) and the skin that must stay outside them: (their triangles, the outer skin vertices (facing
    ``forward``; not the lips' inner sides, which the true shapes press onto the teeth) within a third of the
    ball's radius of them and outside them at rest, those vertices' rest clearance), or None when there are none.
    """
    if mouth is None:
        return None
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    _, labels = components(len(v), t)
    skin_label = labels[skin[0]]
    parts = [lab for lab in np.unique(labels[np.unique(t)]) if lab != skin_label
             and np.linalg.norm(v[labels == lab].mean(0) - mouth[0]) < mouth[1]]
    if not parts:
        return None
    part_t = t[np.isin(labels[t[:, 0]], parts)]
    e1, e2 = v[part_t[:, 1]] - v[part_t[:, 0]], v[part_t[:, 2]] - v[part_t[:, 0]]
    part_t = part_t[np.cross(e1, e2) @ forward > 0]  # their front: the back and insides are no guide for the skin
    facing = vertex_normals(v.astype(np.float32), t.astype(np.uint32))[skin] @ forward > 0.3
    cand = skin[facing]
    clearance, dist, _ = _surface_push(v[cand], v, part_t)
    near = (dist < mouth[1] / 3) & (clearance > 0)
    if not near.any():
        return None
    return part_t, cand[near], clearance[near]


def _surface_push(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> tuple:
    """(signed distance along the nearest triangle's normal, distance, that normal) of ``points`` to the
    surface of ``triangles``."""
    tri_i, bary, dist = nearest_triangles(points, vertices, triangles)
    tri = vertices[triangles[tri_i]]
    closest = (bary[:, :, None] * tri).sum(1)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-18)
    return ((points - closest) * n).sum(1), dist, n


def clear_mouth_parts(rest: np.ndarray, d: np.ndarray, part_t: np.ndarray, near: np.ndarray, clearance: np.ndarray,
                      margin: float = MOUTH_CLEARANCE) -> np.ndarray:
    """Displacements of the ``near`` skin vertices with none pushed into the mouth's parts (the gums through the
    cheeks in mouthFunnel): a vertex whose shaped place lies less than ``margin`` of its rest ``clearance`` outside
    the nearest (shaped) mouth-part triangle, along its normal, is put back out along it. Returns (len(near), 3)."""
    q = rest + d  # the parts stay or follow the jaw
    out = np.array(d[near])
    for _ in range(2):  # a pushed vertex may meet another triangle
        p = rest[near] + out
        gap, _, n = _surface_push(p, q, part_t)
        short = gap < margin * clearance
        if not short.any():
            break
        out[short] += ((margin * clearance - gap)[short])[:, None] * n[short]
    return out


def carry_pieces(dense: np.ndarray, source: ElasticModel, names: tuple[str, ...], params: np.ndarray,
                 vertices: np.ndarray, face: Face, rigid: np.ndarray, eyeballs: np.ndarray,
                 mouth: tuple | None = None, looks: dict | None = None) -> dict:
    """Carry the cloned skin motion in ``dense`` (n, n_vertices, 3), in place, onto the face's other pieces
    (:mod:`.pieces`): those on the skin follow their skin triangle, decal eyes and mouths the landmark field of
    the source's ``params`` (the folded (n, n_c, 3)). The ``eyeballs`` (their vertices) and the ``rigid`` jaw
    keep their motion, except that on a decal face the jaw found from the skin's points is not trusted: what of it
    the field does not move stays. A piece centred within the ``mouth`` ball (centre, radius) is the inside of
    the mouth (ICT's upper teeth lie within 0.8 cm of the mouth's skin): it keeps its motion too. A decal eye
    closes, narrows and looks as a drawn eye does (:func:`~.drawn_eyes.decal_blink`, :func:`~.drawn_eyes.decal_narrow`,
    :func:`decal_eye_looks`, the last from the character's own look expressions ``looks`` where it has them).

    Returns {"decal_eyes": sides, "decal_mouth": bool, "carried_vertices": n, "field_vertices": n} and, on a decal
    face, "eye_looks": where each decal eye's look came from (:func:`decal_eye_looks`)."""
    skin_t = skin_triangles(face)
    pieces = find_pieces(vertices, face, skin_t, still=eyeballs)
    features = pieces.feature_vertices
    if not len(features):  # the skin carries the features: the pieces on it follow it
        carried = pieces.on_skin[~np.isin(pieces.on_skin, rigid)]
        if mouth is not None and len(carried):
            lab = pieces.labels[carried]
            _, inverse = np.unique(lab, return_inverse=True)
            centres = np.stack([np.bincount(inverse, weights=vertices[carried, k]) for k in range(3)], 1)
            centres /= np.bincount(inverse)[:, None]
            carried = carried[np.linalg.norm(centres - mouth[0], axis=1)[inverse] > mouth[1]]
        if len(carried):
            dense[:, carried] = embed(vertices, carried, skin_t, dense)
        _move_copies_as_one(dense, face)
        return {"decal_eyes": [], "decal_mouth": False, "carried_vertices": int(len(carried)), "field_vertices": 0}
    # a decal face (Godette): its features are pieces in front of a skin too coarse for them, which the skin's
    # control points cannot find; the features and the pieces on the skin move by the features' landmark field,
    # the skin stays (folding its coarse triangles about an eye tears the face, and the artist's own shapes
    # move no skin), and so does the jaw found from the skin's points
    dense[:, rigid] = 0.0
    dense[:, face.skin] = 0.0
    moved = np.concatenate([features, pieces.on_skin])
    dense[:, moved] = feature_field(pieces, face, vertices, source.arrays["control_positions"],
                                    tuple(source.control_names), params, names, moved)
    jaw = [s for s, key in enumerate(names) if key in JAW_OPENINGS]
    if pieces.mouth is not None and jaw:  # the skin has no jaw to open: the drawn mouth shows the lips' opening
        dense[np.ix_(jaw, pieces.mouth[0])] -= lip_line_motion(
            pieces, face, vertices, source.arrays["control_positions"], tuple(source.control_names), params[jaw],
            tuple(names[s] for s in jaw)).astype(dense.dtype)
    # the skin stays: what the field moves slides over it (the drawn eyes' own closing below hides on purpose)
    keep_clearance(dense, vertices, face, moved, skin_t, face.triangles[np.isin(face.triangles, moved).all(axis=1)])
    dense[:, pieces.upper_teeth] = 0.0  # fixed to the skull (pieces.mouth_sides)
    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        if key in names and side in pieces.eyes:  # the drawn eye closes on the line between its corners
            members, d = decal_blink(pieces, face, vertices, skin_t, side)
            dense[names.index(key), members] = d
    for s, key in enumerate(names):
        if key in ("eyeBlinkLeft", "eyeBlinkRight") or any((key, side) in EYE_TURNS for side in "LR"):
            continue
        for side in pieces.eyes:  # the others narrow (or open) it toward that line, as far as the source's lids say
            upper, lower = lid_fractions(source.arrays["control_positions"], tuple(source.control_names),
                                            params, names, key, side)
            members, d = decal_narrow(pieces, face, vertices, side, upper, lower)
            dense[s, members] = d
    looks_from = decal_eye_looks(dense, names, vertices, face, pieces, looks)
    m = pieces.mouth[0] if pieces.mouth is not None else np.zeros(0, np.int64)
    side = np.zeros(len(vertices), np.int8)
    side[m] = np.where(pieces.mouth_below, 1, 2)
    parted = m[side[m] != side[face.weld[m]]] if face.weld is not None else m[:0]
    _move_copies_as_one(dense, face, keep=parted)
    return {"decal_eyes": sorted(pieces.eyes), "decal_mouth": pieces.mouth is not None, "carried_vertices": 0,
            "field_vertices": int(len(np.unique(moved))), "eye_looks": looks_from}


def _move_copies_as_one(dense: np.ndarray, face: Face, keep: np.ndarray = ()) -> None:
    """A seam's copies move as their first copy (in place), except the ``keep`` vertices: the copies of a decal
    mouth's seam that the lip line's cut parts (:func:`~.pieces.mouth_sides`)."""
    if face.weld is None:
        return
    mesh = face.mesh[~np.isin(face.mesh, np.asarray(keep, np.int64))]
    dense[:, mesh] = dense[:, face.weld[mesh]]


def _mouth_ball(points: ControlPoints, vertices: np.ndarray) -> tuple | None:
    """(centre, radius): the mouth corners' mid-point and 1.6 inner-eye distances (ICT's back molars are centred
    1.5 from it, its lashes 1.9), or None without those points."""
    need = ("mouth_corner_L", "mouth_corner_R", "eye_inner_L", "eye_inner_R")
    if not all(n in points.names for n in need):
        return None
    v = np.asarray(vertices, np.float64)
    centre = 0.5 * (v[points.vertex("mouth_corner_L")] + v[points.vertex("mouth_corner_R")])
    return centre, 1.6 * float(np.linalg.norm(v[points.vertex("eye_inner_L")] - v[points.vertex("eye_inner_R")]))


def decal_eye_looks(dense: np.ndarray, names: tuple[str, ...], vertices: np.ndarray, face: Face,
                    pieces: Pieces, looks: dict | None = None) -> dict:
    """The eye looks of a decal eye (in place in ``dense``), as a drawn eye looks: only what lies inside the eye
    (:func:`~.drawn_eyes.eye_inside`: iris, pupil, highlights, the white) moves; the outline, the lashes, the other
    eye, the mouth and everything else the landmark field moved stay.

    Where the character has its own look expression for the look (``looks``: :func:`~.eye_looks.look_expressions`;
    which ARKit look of which eye each is, by where it moves that eye's iris: :func:`~.eye_looks.look_keys`), the
    look is that expression's part on the eye's inside: from the character's lookAt, not cloned (Godette:
    eyeLookUpLeft is the left eye's part of her ``look_up``; her ``look_down`` also lowers the lashes, which is
    left out, so that a closed eye looking down stays a line). Otherwise the inside slides
    (:func:`~.eye_looks.decal_look_slide`) as the front of a ball of half the eye's width would move turned by
    ``EYE_LOOK_DEGREES``, held inside the outline. Returns {ARKit key: "<preset> (the character's lookAt)" or
    "slid"} for each look given to a decal eye."""
    if not pieces.eyes:
        return {}
    own = look_keys(looks or {}, pieces, face, vertices)
    still = np.concatenate([pieces.feature_vertices, pieces.on_skin])  # what the landmark field moved
    origin: dict = {}
    for s, name in enumerate(names):
        turns = [(side, EYE_TURNS[(name, side)]) for side in pieces.eyes if (name, side) in EYE_TURNS]
        if not turns:
            continue
        dense[s, still] = 0.0
        for side, (axis, sign) in turns:
            if (name, side) in own:
                preset, inside = own[(name, side)]
                dense[s, inside] = looks[preset][inside].astype(dense.dtype)
                origin[name] = f"{preset} (the character's lookAt)"
                continue
            _, (x0, x1, _, _) = pieces.eyes[side]
            angle = np.radians(EYE_LOOK_DEGREES[0 if axis == 1 else 1])
            # about up (axis 1) by +a: the front moves to +x; about across (axis 0) by -a: the front moves up
            along = 0 if axis == 1 else 1
            amount = (sign if axis == 1 else -sign) * 0.5 * abs(x1 - x0) * np.sin(angle)
            inside, d = decal_look_slide(pieces, face, vertices, side, along, amount)
            dense[s, inside] = d.astype(dense.dtype)
            origin[name] = "slid"
    return origin


def add_shapes(character: Character, keys: tuple[str, ...], dense: np.ndarray,
               replace: bool = False) -> tuple[Character, dict]:
    """``character`` with the cloned shapes added under its naming convention.

    A shape it already has under an ARKit name is kept (``replace``: its deltas replaced). Returns
    (character, {"added": [...], "kept": [...], "replaced": [...]}).
    """
    style = naming_style(character.shape_names)
    have = {canonical(n): s for s, n in enumerate(character.shape_names) if arkit_index(n) is not None}
    rows = []  # (name, indices, positions, normals) per shape, existing first
    for s, name in enumerate(character.shape_names):
        sl = character.shape_slice(s)
        rows.append([name, character.delta_indices[sl], character.delta_positions[sl], character.delta_normals[sl]])
    n0 = vertex_normals(character.vertices, character.triangles)
    report = {"added": [], "kept": [], "replaced": []}
    for key, d in zip(keys, dense):
        if key in have and not replace:
            report["kept"].append(character.shape_names[have[key]])
            continue
        dn = vertex_normals(character.vertices + d, character.triangles) - n0
        offsets, idx, both = sparse_deltas(np.concatenate([d, dn], axis=1)[None], tolerance=1e-6)
        row = [spelled(key, style), idx, both[:, :3], both[:, 3:]]
        if key in have:
            row[0] = character.shape_names[have[key]]
            rows[have[key]] = row
            report["replaced"].append(row[0])
        else:
            rows.append(row)
            report["added"].append(row[0])
    counts = [len(r[1]) for r in rows]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cat = (lambda i, shape, dt: np.concatenate([np.asarray(r[i], dt).reshape(shape) for r in rows])  # noqa: E731
           if rows else np.zeros((0,) + shape[1:], dt))
    out = character.with_parts(
        shape_names=tuple(r[0] for r in rows), delta_offsets=offsets,
        delta_indices=cat(1, (-1,), np.uint32), delta_positions=np.ascontiguousarray(cat(2, (-1, 3), np.float32)),
        delta_normals=np.ascontiguousarray(cat(3, (-1, 3), np.float32)),
    )
    return out, report
