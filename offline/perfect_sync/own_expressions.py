"""The character's own VRM expressions against the cloned shapes of the same meaning: the better one is used.

Where the artist already made an expression for an ARKit channel (``Blink_L``
for eyeBlinkLeft, ``A`` for jawOpen, ``O`` for mouthFunnel, ``U`` for
mouthPucker: :data:`CHANNEL_EXPRESSIONS`), the clone must not be worse than
it. Both are measured at weight 1 on the face mesh:

* **agreement**: the cosine of the two displacement fields and the ratio of
  their norms (clone / expression);
* **torn lines**: the largest change of an edge's length relative to its rest
  length, over the face mesh's edges longer than 1 % of the inner-eye
  distance (a drawn line or a lid torn apart or folded flat);
* **vanishing**: the share of the drawn features (the decal eyes and mouth, the
  pieces lying on the skin: lashes, brows) that is in front of everything at
  rest and goes behind the skin or another mesh (the hair) in the shape.

The clone is worse, and the expression is used in its place, when it tears
more (``TEAR_FACTOR`` times the expression's, and by more than ``TEAR_MIN``),
hides more of the drawn features (by ``VANISH_MORE``), or moves otherwise
than the expression (cosine under ``AGREE``). Every channel with an
expression is reported: which one was used and why, with the measures.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.mapping.expressions import PRESET_SPELLINGS
from facepuppet.runtime.model.character import Character

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.pieces import Pieces
from facepuppet.offline.perfect_sync.triangles import skin_front_depth

#: ARKit channel -> the VRM 0.x preset meaning the same thing on its own (the vowels and blinks; the looks of
#: a decal eye are taken from the character's lookAt already, :func:`.transfer.decal_eye_looks`)
CHANNEL_EXPRESSIONS = {"eyeBlinkLeft": "Blink_L", "eyeBlinkRight": "Blink_R", "jawOpen": "A",
                       "mouthFunnel": "O", "mouthPucker": "U"}
TEAR_FACTOR, TEAR_MIN = 2.0, 0.5  # worse: edges strained more than twice the expression's and by 0.5 more
VANISH_MORE = 0.05  # worse: this share more of the drawn features hidden than the expression hides
AGREE = 0.3  # worse: a cosine to the expression under this (it moves something else)
HIDDEN = 0.001  # a drawn vertex this many inner-eye distances behind the frontmost surface is hidden (decals lie
# a millimetre or two in front of the skin: a brow pushed back that far is gone)


def expression_deltas(character: Character, preset: str) -> np.ndarray | None:
    """Dense displacements (n_vertices, 3) of the character's expression for the VRM 0.x ``preset`` (any
    spelling among its expressions), its binds' weighted sum of its shapes; None when it has none that moves."""
    ex = character.expressions
    if ex is None:
        return None
    for e, name in enumerate(ex.presets):
        if PRESET_SPELLINGS.get(str(name).lower()) != preset:
            continue
        shapes, weights = ex.binds(e)
        d = np.zeros((character.n_vertices, 3))
        for s, w in zip(shapes.astype(np.int64), weights):
            sl = character.shape_slice(int(s))
            np.add.at(d, character.delta_indices[sl].astype(np.int64),
                      float(w) * character.delta_positions[sl].astype(np.float64))
        if np.abs(d).max(initial=0.0) > 0:
            return d
    return None


def _edges(face: Face) -> np.ndarray:
    t = face.unwelded if face.unwelded is not None else face.triangles
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def tear(vertices: np.ndarray, d: np.ndarray, edges: np.ndarray, es: float) -> float:
    """Largest |length change / rest length| over ``edges`` longer than 1 % of ``es`` under displacements ``d``."""
    v = np.asarray(vertices, np.float64)
    rest = np.linalg.norm(v[edges[:, 1]] - v[edges[:, 0]], axis=1)
    keep = rest > 0.01 * es
    moved = np.linalg.norm(v[edges[keep, 1]] + d[edges[keep, 1]] - v[edges[keep, 0]] - d[edges[keep, 0]], axis=1)
    return float(np.abs(moved / rest[keep] - 1.0).max(initial=0.0))


def hidden_share(character: Character, face: Face, drawn: np.ndarray, d: np.ndarray, es: float) -> float:
    """Share of the ``drawn`` vertices in front of every other surface at rest that go behind one (the skin, the
    other meshes: the hair) under displacements ``d`` (the drawn pieces themselves are not occluders)."""
    if not len(drawn):
        return 0.0
    t = np.asarray(character.triangles, np.int64)
    mine = np.zeros(character.n_vertices, bool)
    mine[drawn] = True
    occluders = t[~mine[t].any(axis=1)]

    def shown(displaced):
        local = face.to_frame(displaced)
        front = skin_front_depth(local[drawn, :2], local, occluders)
        return ~(front > local[drawn, 2] + HIDDEN * es)

    v = character.vertices.astype(np.float64)
    at_rest = shown(v)
    if not at_rest.any():
        return 0.0
    return float((at_rest & ~shown(v + d)).sum() / at_rest.sum())


def measure(character: Character, face: Face, drawn: np.ndarray, clone: np.ndarray, own: np.ndarray,
            es: float) -> dict:
    """The module doc's measures of the cloned and the character's own displacements (n_vertices, 3)."""
    mesh = face.mesh
    a, b = clone[mesh].ravel(), own[mesh].ravel()
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    edges = _edges(face)
    v = character.vertices
    return {"cosine": round(float(a @ b) / (na * nb), 3) if na > 0 and nb > 0 else 0.0,
            "magnitude_ratio": round(na / nb, 3) if nb > 0 else None,
            "tear_clone": round(tear(v, clone, edges, es), 3), "tear_own": round(tear(v, own, edges, es), 3),
            "hidden_clone": round(hidden_share(character, face, drawn, clone, es), 3),
            "hidden_own": round(hidden_share(character, face, drawn, own, es), 3)}


def verdict(m: dict) -> list[str]:
    """Why the clone is worse than the character's own expression by the measures ``m`` (empty: it is not)."""
    why = []
    if m["tear_clone"] > TEAR_FACTOR * m["tear_own"] + TEAR_MIN:
        why.append(f"torn lines: an edge's length changes by {m['tear_clone']:.2f} of itself (the expression's "
                   f"{m['tear_own']:.2f})")
    if m["hidden_clone"] > m["hidden_own"] + VANISH_MORE:
        why.append(f"vanishing: {100 * m['hidden_clone']:.0f} % of the drawn features go behind the skin or hair "
                   f"(the expression's {100 * m['hidden_own']:.0f} %)")
    if m["cosine"] < AGREE:
        why.append(f"moves otherwise: cosine {m['cosine']:.2f} to the expression (< {AGREE})")
    return why


def prefer_own(character: Character, face: Face, pieces: Pieces | None, keys: tuple[str, ...], dense: np.ndarray,
               es: float) -> dict:
    """For each channel of ``keys`` the character has an expression for, the clone in ``dense`` (n, n_vertices, 3)
    replaced by it (in place) where the clone is worse (see the module doc). Returns {channel: {"used": "clone" or
    "<preset> (the character's own)", "why": text, measures}}."""
    drawn = np.zeros(0, np.int64)
    if pieces is not None:
        drawn = np.unique(np.concatenate([pieces.feature_vertices, pieces.on_skin]).astype(np.int64))
    out = {}
    for key, preset in CHANNEL_EXPRESSIONS.items():
        if key not in keys:
            continue
        own = expression_deltas(character, preset)
        if own is None:
            continue
        s = keys.index(key)
        clone = dense[s].astype(np.float64)
        m = measure(character, face, drawn, clone, own, es)
        why = verdict(m)
        if why:
            dense[s] = own.astype(dense.dtype)
            out[key] = {"used": f"{preset} (the character's own)", "why": "the clone is worse: " + "; ".join(why), **m}
        else:
            out[key] = {"used": "clone", "why": "no worse than the character's own " + preset, **m}
    return out
