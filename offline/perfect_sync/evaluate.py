"""How good cloned perfect-sync shapes are: against true shapes, against an artist's, and at the lids.

* :func:`truth_errors`: on a character whose true ARKit expressions are known
  (an ICT variant): per shape the RMS error over the skin vertices the true
  shape moves (more than 1 % of its largest displacement), relative to that
  largest displacement (as fit-elastic reports its own error);
* :func:`pair_similarity`: against an artist's shape that means the same
  (Godette's ``blink_left`` for ``eyeBlinkLeft``): cosine of the two
  displacement fields over the face mesh, and the ratio of their norms; a
  cloned side written ``a+b`` is the sum of those shapes (her ``look_up``
  turns both eyes: ``eyeLookUpLeft+eyeLookUpRight``; against one eye's
  shape alone the cosine cannot pass 0.71);
* :func:`godette_pairs`: every pair of :data:`GODETTE_PAIRS` the character
  has, each with where its cloned side came from: an eye look of a decal
  eye given by the character's own look expression is "from the character's
  lookAt", a channel perfect-sync took from the character's own expression
  because the clone was worse is "the character's own expression" (neither
  cosine says anything of the cloning; the replaced clone's are kept), the
  others "cloned";
* :func:`mid_lid_gap`: the vertical gap between the lids half way between
  their inner and outer control points, at rest and in a shape.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.perfect_sync.face import Face

# ARKit shape → the VRM 0.x preset / Godette shape meaning the same thing (canonical ARKit key first).
GODETTE_PAIRS = (
    ("eyeBlinkLeft", "blink_left"), ("eyeBlinkRight", "blink_right"), ("jawOpen", "ah"),
    ("mouthFunnel", "oh"), ("mouthPucker", "uu"), ("mouthStretchLeft", "ee"), ("mouthSmileLeft", "ih"),
    ("eyeLookUpLeft", "look_up"), ("eyeLookDownLeft", "look_down"), ("eyeLookOutLeft", "look_left"),
    ("eyeLookInLeft", "look_right"), ("browDownLeft", "angled_eyebrows"),
    # her looks turn both eyes (look_left: towards her left, the left eye out and the right one in)
    ("eyeLookUpLeft+eyeLookUpRight", "look_up"), ("eyeLookDownLeft+eyeLookDownRight", "look_down"),
    ("eyeLookOutLeft+eyeLookInRight", "look_left"), ("eyeLookInLeft+eyeLookOutRight", "look_right"),
)


def truth_errors(truth: Character, cloned: Character, face: Face) -> dict:
    """{canonical ARKit key: relative RMS error} of each shape ``cloned`` has beyond ``truth``'s own count.

    ``truth`` holds the true shapes under any ARKit spelling (an unsided key the truth splits is the sum
    of its sides); ``cloned`` is ``truth``'s mesh with the cloned shapes after its own ``truth.n_shapes``.
    """
    true = truth.dense_deltas()
    by = {canonical(n): s for s, n in enumerate(truth.shape_names)}
    dense = cloned.dense_deltas()
    out = {}
    for s in range(truth.n_shapes, cloned.n_shapes):
        key = canonical(cloned.shape_names[s])
        if key in by:
            t = true[by[key]]
        elif key + "Left" in by and key + "Right" in by:
            t = true[by[key + "Left"]] + true[by[key + "Right"]]
        else:
            continue
        length = np.linalg.norm(t[face.skin], axis=1)
        if length.max() <= 0:
            continue
        moved = length > 0.01 * length.max()
        err = np.linalg.norm(dense[s][face.skin][moved] - t[face.skin][moved], axis=1)
        out[key] = float(np.sqrt(np.mean(err**2)) / length.max())
    return out


def pair_similarity(character: Character, cloned_name: str, artist_name: str, vertices: np.ndarray) -> dict:
    """{"cosine", "magnitude_ratio"} of two shapes of ``character`` over ``vertices`` (cloned / artist);
    ``cloned_name`` may be several shapes joined by "+" (their sum)."""
    dense = character.dense_deltas()
    a = sum(dense[character.shape_names.index(n)] for n in cloned_name.split("+"))[vertices].astype(np.float64)
    a = a.ravel()
    b = dense[character.shape_names.index(artist_name)][vertices].astype(np.float64).ravel()
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return {"cosine": float(a @ b / (na * nb)) if na > 0 and nb > 0 else None,
            "magnitude_ratio": float(na / nb) if nb > 0 else None}


LOOKAT = "the character's lookAt"
OWN = "the character's own expression (the clone was worse)"


def godette_pairs(character: Character, eye_looks: dict, vertices: np.ndarray,
                  own_expressions: dict | None = None) -> dict:
    """{"<cloned>~<artist>": {"cosine", "magnitude_ratio", "from"}} for each pair of :data:`GODETTE_PAIRS` whose
    shapes ``character`` has, over ``vertices``; "from" is :data:`LOOKAT` when every cloned shape of the pair took
    its look from the character's own look expression (``eye_looks``: perfect-sync's report["pieces"]
    ["eye_looks"]), :data:`OWN` when perfect-sync used the character's own expression in its place
    (``own_expressions``: its report["own_expressions"]; the pair's cosine then says nothing of the cloning, and
    "clone_cosine", "clone_magnitude_ratio" are the clone's against that expression), else "cloned"."""
    own_expressions = own_expressions or {}
    out = {}
    for key, artist in GODETTE_PAIRS:
        parts = key.split("+")
        if artist not in character.shape_names or not all(k in character.shape_names for k in parts):
            continue
        pair = pair_similarity(character, key, artist, vertices)
        replaced = [own_expressions[k] for k in parts if k in own_expressions and own_expressions[k]["used"] != "clone"]
        if all("lookAt" in str(eye_looks.get(k, "")) for k in parts):
            pair["from"] = LOOKAT
        elif replaced and len(replaced) == len(parts):
            pair["from"] = OWN
            if len(parts) == 1:
                pair["clone_cosine"] = replaced[0]["cosine"]
                pair["clone_magnitude_ratio"] = replaced[0]["magnitude_ratio"]
        else:
            pair["from"] = "cloned"
        out[f"{key}~{artist}"] = pair
    return out


def mid_lid_gap(character: Character, face: Face, points: ControlPoints, side: str,
                delta: np.ndarray) -> tuple[float, float]:
    """(rest, shaped) vertical gap (units, along the face's up) between the skin vertices nearest the
    mid-points of the upper and lower lid of ``side`` ("L"/"R"); ``delta`` (n, 3) the shape's deltas."""
    v = character.vertices.astype(np.float64)
    skin = face.skin
    up_axis = face.frame[1]

    def near(p):
        return int(skin[np.argmin(np.linalg.norm(v[skin] - p, axis=1))])

    def mid(lid):
        return 0.5 * (v[points.vertex(f"lid_{lid}_inner_{side}")] + v[points.vertex(f"lid_{lid}_outer_{side}")])

    up, low = near(mid("upper")), near(mid("lower"))
    rest = float((v[up] - v[low]) @ up_axis)
    return rest, float((v[up] + delta[up] - v[low] - delta[low]) @ up_axis)


def lid_closure(truth: Character, cloned: Character, face: Face, points: ControlPoints) -> dict:
    """{eyeBlinkLeft / eyeBlinkRight: {"rest", "true", "cloned"}}: the mid-lid gap (:func:`mid_lid_gap`, units) at
    rest, in the true blink and in the cloned one; ``cloned`` as in :func:`truth_errors`, ``points`` the lid
    control points on ``truth``'s mesh (a known set, not a proposal: the measure must not depend on what it
    measures)."""
    true = truth.dense_deltas()
    dense = cloned.dense_deltas()
    by = {canonical(n): s for s, n in enumerate(truth.shape_names)}
    mine = {canonical(cloned.shape_names[s]): s for s in range(truth.n_shapes, cloned.n_shapes)}
    out = {}
    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        if key not in by or key not in mine:
            continue
        rest, shut = mid_lid_gap(truth, face, points, side, true[by[key]])
        _, closed = mid_lid_gap(truth, face, points, side, dense[mine[key]])
        out[key] = {"rest": rest, "true": shut, "cloned": closed}
    return out
