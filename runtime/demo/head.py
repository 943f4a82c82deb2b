"""The embedded demo character: a procedural head with ARKit-named expression shapes.

``build_demo_character()`` needs no data files: it assembles the parts of
:mod:`demo_head_parts` (skin with a mouth slit, eyeballs, lids, teeth, mouth
cavity) and derives each expression shape as a smooth displacement field:
the jaw rotates about a hinge below the ears, lids slide over the eyeballs
along their shells, eyeballs turn about their centres, the rest are Gaussian
pulls on the skin. Left is the character's own left (x > 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.demo import head_parts as parts
from facepuppet.runtime.demo.head_parts import gauss
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.geometry import smoothstep, vertex_normals

MATERIALS = ("skin", "lips", "eye", "teeth", "mouth")
# specular, shininess per material; the kind code comes from MATERIAL_KINDS
_MATERIAL_LOOK = {"skin": (0.25, 18.0), "lips": (0.35, 30.0), "eye": (0.8, 80.0), "teeth": (0.5, 40.0),
                  "mouth": (0.0, 1.0)}
JAW_OPEN_ANGLE = np.radians(16.0)
_SIDES = {"Left": 1.0, "Right": -1.0}


@dataclass
class _Head:
    """The assembled neutral and the per-vertex facts the shapes need."""

    vertices: np.ndarray  # (n, 3) float64, cm
    ranges: dict  # part name -> slice of vertices
    skin: parts.Part
    lids: dict  # (side, upper) -> Part
    pieces: dict  # part name -> Part, in vertex order
    jaw: np.ndarray  # (n,) how much each vertex follows the jaw, 0..1

    def mask(self, *names: str) -> np.ndarray:
        m = np.zeros(len(self.vertices), bool)
        for name in names:
            m[self.ranges[name]] = True
        return m


def _rotate_x(points, centre, angle):
    """Rotate (n, 3) points about the x axis through ``centre`` by per-point ``angle`` (rad)."""
    p = points - centre
    c, s = np.cos(angle), np.sin(angle)
    return centre + np.stack([p[:, 0], c * p[:, 1] - s * p[:, 2], s * p[:, 1] + c * p[:, 2]], -1)


def _rotate_y(points, centre, angle):
    p = points - centre
    c, s = np.cos(angle), np.sin(angle)
    return centre + np.stack([c * p[:, 0] + s * p[:, 2], p[:, 1], -s * p[:, 0] + c * p[:, 2]], -1)


def _assemble() -> _Head:
    skin = parts.skin()
    mouth_front = skin.vertices[skin.params["mouth"]]
    lip_z = float(mouth_front[:, 2].max())
    slit_y = float(mouth_front[np.argmax(mouth_front[:, 2]), 1])
    pieces = {"skin": skin}
    lids = {}
    for side_name, side in _SIDES.items():
        pieces[f"eye{side_name}"] = parts.eyeball(side)
        for upper in (True, False):
            lids[side, upper] = pieces[f"lid{'Upper' if upper else 'Lower'}{side_name}"] = parts.eyelid(side, upper)
    pieces["teethUpper"] = parts.teeth(True, lip_z, slit_y)
    pieces["teethLower"] = parts.teeth(False, lip_z, slit_y)
    pieces["bag"] = parts.mouth_bag(skin)
    ranges, start = {}, 0
    for name, part in pieces.items():
        ranges[name] = slice(start, start + len(part.vertices))
        start += len(part.vertices)
    vertices = np.concatenate([p.vertices for p in pieces.values()])
    head = _Head(vertices, ranges, skin, lids, pieces, np.zeros(len(vertices)))
    head.jaw = _jaw_weights(head, slit_y)
    return head


def _jaw_weights(head: _Head, slit_y: float) -> np.ndarray:
    """How far each vertex follows the jaw: 1 on the chin and lower lip, 0 above the mouth and on the neck."""
    w = np.zeros(len(head.vertices))
    sk = head.skin
    v = sk.vertices
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    rel = sk.params["rel"]
    ramp = smoothstep(2.6, -1.6, rel)  # ~0.5 at the lip line beside the mouth
    inside = 1.0 - smoothstep(parts.MOUTH_HALF_WIDTH - 1.0, parts.MOUTH_HALF_WIDTH + 1.4, np.abs(x))
    lower = sk.params["lower"]
    follow = np.where(lower, ramp + (1 - ramp) * inside, ramp * (1 - inside))
    follow *= smoothstep(-1.5, 2.5, z)  # the back of the head and the nape stay
    follow *= smoothstep(-15.0, -11.0, y + 0.35 * (z - 6.0))  # fade down the throat
    w[head.ranges["skin"]] = follow
    w[head.ranges["teethLower"]] = 1.0
    bag = head.pieces["bag"].params
    w[head.ranges["bag"]] = (1 - bag["t"]) * follow[bag["rim"]] + bag["t"] * (bag["sigma"] < 0)
    return w


# -- shapes ------------------------------------------------------------------
def _skin_field(head: _Head, field: np.ndarray) -> np.ndarray:
    """(n_skin, 3) displacement placed on the skin vertices of a full (n, 3) array, face-masked."""
    out = np.zeros_like(head.vertices)
    out[head.ranges["skin"]] = field * head.skin.params["front"][:, None]
    return out


def _jaw_rotation(head: _Head, angle: float) -> np.ndarray:
    w = head.jaw
    moved = _rotate_x(head.vertices, parts.JAW_HINGE, angle * w)
    return np.where((w > 0)[:, None], moved - head.vertices, 0.0)


def _jaw_translation(head: _Head, offset) -> np.ndarray:
    return head.jaw[:, None] * np.asarray(offset, dtype=np.float64)


def _lids(head: _Head, side: float, upper_to=None, lower_to=None) -> np.ndarray:
    """Slide the lid margins of one eye to new elevations (functions of alpha, rad)."""
    out = np.zeros_like(head.vertices)
    side_name = "Left" if side > 0 else "Right"
    for upper, target in ((True, upper_to), (False, lower_to)):
        if target is None:
            continue
        lid = head.lids[side, upper]
        a, s = lid.params["alpha"], lid.params["s"]
        beta = parts.lid_elevation(a, s, upper, margin=target(a))
        sl = head.ranges[f"lid{'Upper' if upper else 'Lower'}{side_name}"]
        out[sl] = parts.lid_points(side, a, beta, s, upper) - head.vertices[sl]
    return out


def _eye_turn(head: _Head, side: float, pitch: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """Turn one eyeball: pitch > 0 looks up, yaw > 0 looks towards +x."""
    out = np.zeros_like(head.vertices)
    sl = head.ranges[f"eye{'Left' if side > 0 else 'Right'}"]
    p = head.vertices[sl]
    centre = parts.eye_centre(side)
    out[sl] = _rotate_y(_rotate_x(p, centre, -pitch), centre, yaw) - p
    return out


def _sided_shapes(head: _Head, side: float) -> dict:
    v = head.skin.vertices
    x, y = v[:, 0], v[:, 1]
    sx = side * x  # > 0 on this side
    rel = head.skin.params["rel"]
    corner = gauss(sx, rel, parts.MOUTH_HALF_WIDTH, 0.15, 1.5, 1.25)
    cheek = gauss(sx, y, 3.3, parts.MOUTH_Y + 3.4, 1.5, 1.3)
    brow = gauss(sx, y, 2.7, 2.6, 2.1, 1.05)
    up = parts.lid_margin
    opening = lambda a: up(a, True) - up(a, False)  # noqa: E731
    one = np.ones_like(x)

    def vec(*c):
        return np.stack([side * c[0] * one, c[1] * one, c[2] * one], -1)

    def arch(a):  # 1 mid-lid, 0 at the corners
        return np.cos(np.clip(a / parts.LID_CORNER, -1, 1) * np.pi / 2)

    shapes = {
        "eyeBlink": _lids(head, side, lambda a: up(a, False) - np.radians(3),
                          lambda a: up(a, False) + 0.15 * opening(a)),
        "eyeWide": _lids(head, side, lambda a: up(a, True) + np.radians(22) * arch(a)),
        "eyeSquint": _lids(head, side, lambda a: up(a, True) - 0.15 * opening(a),
                           lambda a: up(a, False) + 0.4 * opening(a))
        + _skin_field(head, gauss(sx, y, 3.4, -1.0, 1.4, 0.9)[:, None] * vec(0.0, 0.35, 0.15)),
        "eyeLookUp": _eye_turn(head, side, pitch=np.radians(24))
        + _lids(head, side, lambda a: up(a, True) + np.radians(6) * arch(a)),
        "eyeLookDown": _eye_turn(head, side, pitch=-np.radians(24))
        + _lids(head, side, lambda a: up(a, True) - 0.35 * opening(a), lambda a: 1.15 * up(a, False)),
        "eyeLookIn": _eye_turn(head, side, yaw=-side * np.radians(28)),
        "eyeLookOut": _eye_turn(head, side, yaw=side * np.radians(28)),
        "mouthSmile": _skin_field(head, corner[:, None] * vec(0.4, 0.75, -0.22)
                                  + cheek[:, None] * vec(0.1, 0.35, 0.25)),
        "mouthFrown": _skin_field(head, corner[:, None] * vec(0.15, -0.65, -0.1)
                                  + gauss(sx, rel, 1.8, -2.0, 1.5, 1.2)[:, None] * vec(0, -0.2, 0)),
        "mouthDimple": _skin_field(head, corner[:, None] * vec(0.35, 0.0, -0.45)),
        "mouthStretch": _skin_field(head, corner[:, None] * vec(0.55, -0.35, -0.2)),
        "mouthPress": _skin_field(head, gauss(sx, rel, 1.3, 0.0, 1.5, 0.8)[:, None] * vec(0, 0, -0.25)
                                  - (rel * gauss(sx, rel, 1.3, 0.0, 1.5, 0.8))[:, None] * vec(0, 0.25, 0)),
        "mouthLowerDown": _skin_field(head, (head.skin.params["lower"] * gauss(sx, rel, 1.2, -0.4, 1.4, 0.9))[:, None]
                                      * vec(0, -0.5, 0.05)),
        "mouthUpperUp": _skin_field(head, (~head.skin.params["lower"] * gauss(sx, rel, 1.2, 0.4, 1.4, 0.9))[:, None]
                                    * vec(0, 0.5, 0.05)),
        "browDown": _skin_field(head, brow[:, None] * vec(-0.25, -0.5, 0.12)),
        "browOuterUp": _skin_field(head, gauss(sx, y, 4.4, 2.7, 1.5, 1.3)[:, None] * vec(0, 0.75, 0)),
        "cheekSquint": _skin_field(head, cheek[:, None] * vec(0.05, 0.4, 0.15)),
        "noseSneer": _skin_field(head, gauss(sx, y, 1.3, -2.9, 0.9, 1.0)[:, None] * vec(0.05, 0.35, 0.05)),
    }
    return shapes


def _expression_fields(head: _Head) -> dict:
    """Dense displacement (n, 3) cm per ARKit shape name."""
    v = head.skin.vertices
    x, y = v[:, 0], v[:, 1]
    rel, lower = head.skin.params["rel"], head.skin.params["lower"]
    lips = np.exp(-((x / 2.4) ** 4)) * np.exp(-((rel / 1.2) ** 2))
    zero = np.zeros_like(x)
    fields = {}
    for side_name, side in _SIDES.items():
        for base, dense in _sided_shapes(head, side).items():
            fields[base + side_name] = dense
    open_ = np.where(lower, -1.0, 1.0) * np.exp(-((x / 1.7) ** 2)) * np.exp(-((rel / 0.9) ** 2))
    lip_close = np.where(lower, np.exp(-((rel / 1.1) ** 2)), 0.0) * np.exp(-((x / 2.6) ** 4))
    close = np.zeros_like(head.vertices)
    close[head.ranges["skin"]] = _rotate_x(v, parts.JAW_HINGE, -0.8 * JAW_OPEN_ANGLE * lip_close) - v
    fields.update({
        "jawOpen": _jaw_rotation(head, JAW_OPEN_ANGLE),
        "jawForward": _jaw_translation(head, (0.0, 0.0, 0.7)),
        "jawLeft": _jaw_translation(head, (0.9, 0.0, 0.0)),
        "jawRight": _jaw_translation(head, (-0.9, 0.0, 0.0)),
        "mouthClose": close,
        "mouthFunnel": _skin_field(head, np.stack([-0.28 * x * lips, 0.5 * open_, 1.0 * lips], -1)),
        "mouthPucker": _skin_field(head, np.stack([-0.38 * x * lips, -0.25 * rel * lips, 1.2 * lips], -1)),
        "mouthLeft": _skin_field(head, np.stack([0.8 * lips, zero, zero], -1)),
        "mouthRight": _skin_field(head, np.stack([-0.8 * lips, zero, zero], -1)),
        "mouthRollLower": _skin_field(head, (lower * lips)[:, None] * np.array([0.0, 0.15, -0.35])),
        "mouthRollUpper": _skin_field(head, (~lower * lips)[:, None] * np.array([0.0, -0.15, -0.35])),
        "mouthShrugLower": _skin_field(head, (lower * gauss(x, rel, 0, -1.2, 2.2, 1.4))[:, None]
                                       * np.array([0.0, 0.35, 0.2])),
        "mouthShrugUpper": _skin_field(head, (~lower * lips)[:, None] * np.array([0.0, 0.25, 0.1])),
        "browInnerUp": _skin_field(head, (gauss(x, y, 1.3, 2.6, 1.3, 1.3) + gauss(x, y, -1.3, 2.6, 1.3, 1.3))[:, None]
                                   * np.array([0.0, 0.7, 0.05])),
        "cheekPuff": _skin_field(head, (gauss(np.abs(x), rel, 3.0, 0.9, 1.5, 1.6))[:, None]
                                 * np.stack([0.6 * np.sign(x), zero, 0.45 + zero], -1)),
    })
    # the mouth bag hangs from the lips: its rim follows them, deeper rings its own (jaw) motion
    bag, params = head.ranges["bag"], head.pieces["bag"].params
    t = params["t"][:, None]
    for dense in fields.values():
        dense[bag] = (1 - t) * dense[head.ranges["skin"].start + params["rim"]] + t * dense[bag]
    return fields


def _shape_deltas(head: _Head, neutral: np.ndarray, triangles: np.ndarray, fields: dict, names):
    """Positions and normal deltas of each shape on one shared sparse index set."""
    n = len(neutral)
    base_normals = vertex_normals(neutral, triangles)
    # triangles of each vertex, for normals recomputed locally
    corner_tri = np.repeat(np.arange(len(triangles)), 3)
    order = np.argsort(triangles.reshape(-1), kind="stable")
    starts = np.searchsorted(triangles.reshape(-1)[order], np.arange(n + 1))
    presence = np.zeros((len(names), n, 3), np.float32)
    pos = np.zeros((len(names), n, 3), np.float32)
    nor = np.zeros((len(names), n, 3), np.float32)
    for k, name in enumerate(names):
        d = fields[name].astype(np.float32)
        d[np.linalg.norm(d, axis=1) < 1e-4] = 0.0
        moved = np.flatnonzero(np.any(d != 0, axis=1))
        near = np.unique(triangles[_tris_of(moved, order, starts, corner_tri)])
        ring = np.sort(_tris_of(near, order, starts, corner_tri))
        sub = triangles[ring]
        deformed = neutral + d
        dn = vertex_normals(deformed, sub)[near] - base_normals[near]
        pos[k] = d
        nor[k, near] = dn
        presence[k, :, 0] = np.abs(d).sum(1)
        presence[k, near, 0] += np.abs(dn).sum(1)
    offsets, indices, _ = sparse_deltas(presence)
    rows = np.repeat(np.arange(len(names)), np.diff(offsets))
    return offsets, indices, pos[rows, indices], nor[rows, indices]


def _tris_of(vertices, order, starts, corner_tri):
    if len(vertices) == 0:
        return np.zeros(0, np.int64)
    spans = [order[starts[v] : starts[v + 1]] for v in vertices]
    return np.unique(corner_tri[np.concatenate(spans)])


def build_demo_character() -> Character:
    """The procedural demo head with ARKit-named expression shapes.

    Returns
    -------
    Character
        units cm, y up, x the character's left, looking along +z; about 13k
        vertices; materials skin, lips, eye, teeth, mouth; shapes named as in
        :data:`facepuppet.runtime.mapping.channels.ARKIT_NAMES`. Deterministic.
    """
    head = _assemble()
    pieces = head.pieces
    tris, mats, colors = [], [], []
    for name, part in pieces.items():
        tris.append(part.triangles + head.ranges[name].start)
        mats.append([MATERIALS.index(m) for m in part.materials])
        colors.append(part.colors)
    triangles = np.concatenate(tris).astype(np.uint32)
    neutral = head.vertices.astype(np.float32)
    fields = _expression_fields(head)
    names = tuple(sorted(fields, key=_arkit_order))
    offsets, indices, positions, normals = _shape_deltas(head, neutral, triangles.astype(np.int64), fields, names)
    params = np.array([[*_MATERIAL_LOOK[m], MATERIAL_KINDS[m], 0.0] for m in MATERIALS], np.float32)
    return Character(
        name="demo head",
        units="cm",
        vertices=neutral,
        triangles=triangles,
        triangle_material=np.concatenate(mats).astype(np.uint16),
        vertex_color=np.clip(np.concatenate(colors), 0, 1).astype(np.float32),
        material_names=MATERIALS,
        material_params=params,
        pivot=np.array([0.0, -9.5, -1.8], np.float32),
        shape_names=names,
        delta_offsets=offsets,
        delta_indices=indices,
        delta_positions=positions,
        delta_normals=normals,
        metadata={"settings": {"generator": "facepuppet demo head", "version": 1}},
    )


def _arkit_order(name: str) -> int:

    return ARKIT_NAMES.index(name)
