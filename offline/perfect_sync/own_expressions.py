"""The cloned shapes' visible defects, and the character's own VRM expressions used where the clone is worse.

A defect a viewer sees at once is measured on every cloned shape at
weight 1, on the drawn pieces of a decal face (its eyes and mouth, the
pieces lying on its skin: lashes, brows; :mod:`.pieces`; a face with its
features in the skin, ICT's, is not measured: its thousands of lash and
film vertices against its skin would cost minutes a shape):

* **vanishing**: per drawn piece, the share of it (sampled over its
  triangles) that is in front of every other surface at rest and goes behind
  the skin or another mesh (the hair) in the shape: a brow pushed a few
  millimetres back, a lash line closing into the skin, shows as torn or gone
  (Godette's "eye lines break apart" and "brows vanish" were these);
* **folding**: per drawn piece, the share of its front-view area (its
  triangles' areas seen from the front at rest) whose triangles turn over in
  the shape (the front-view winding flips): a piece folded across itself is
  drawn inside out, whether or not anything hides it;
* **poking through**: per drawn piece, the largest share of one of its cross
  bands that the skin shows through between triangle corners all in front of
  it (:mod:`.poke_through`): a notch cut across a brow, which reads as a hook.

Where the artist already made an expression for an ARKit channel (``Blink_L``
for eyeBlinkLeft, ``A`` for jawOpen, ``O`` for mouthFunnel, ``U`` for
mouthPucker: :data:`CHANNEL_EXPRESSIONS`), the clone is compared with it as
well (the cosine of the two displacement fields over the face mesh and the
ratio of their norms) and is **worse**, so that the expression is used in
its place, when it hides, folds or lets the skin through more of a drawn piece (by ``VANISH_MORE``
of it) or moves otherwise (cosine under ``AGREE``). Each such
channel is reported with what was used and why; a shape with a defect and
no expression to fall back on is reported as defective.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.mapping.expressions import PRESET_SPELLINGS
from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.pieces import Pieces
from facepuppet.offline.perfect_sync.poke_through import PokeThrough
from facepuppet.offline.perfect_sync.triangles import skin_front_depth

#: ARKit channel -> the VRM 0.x preset meaning the same thing on its own (the vowels and blinks; the looks of
#: a decal eye are taken from the character's lookAt already, :func:`.transfer.decal_eye_looks`)
CHANNEL_EXPRESSIONS = {"eyeBlinkLeft": "Blink_L", "eyeBlinkRight": "Blink_R", "jawOpen": "A",
                       "mouthFunnel": "O", "mouthPucker": "U"}
VANISH_MORE = 0.15  # worse: a drawn piece with this share more of it hidden than the expression hides (Godette's
# blinks: her own hide 75 % of her eye's largest piece, leaving the closed lash line; the clone's all of it)
VANISHED = 0.25  # a defect: a drawn piece with this share of it newly hidden
POKED = 0.25  # a defect: a cross band of a drawn piece with this share of it cut by the skin between its corners
# (her own expressions: 0 on every piece; her cloned outer brow raises with the skin's clearance kept at the
# corners only: 0.81)
FOLDED = 0.25  # a defect: a drawn piece with this share of its front-view area turned over
FLAT = 1e-4  # a triangle whose front-view area is under this fraction of its piece's largest is seen edge-on:
# its winding says nothing
AGREE = 0.3  # worse: a cosine to the expression under this (it moves something else)
HIDDEN = 0.001  # a drawn point this many inner-eye distances behind the frontmost surface is hidden (decals lie
# a millimetre or two in front of the skin: a brow pushed back that far is gone)
SAMPLES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.2, 0.2, 0.6]])


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


class Drawn:
    """The drawn pieces of a face and what their defects are measured against (see the module doc)."""

    def __init__(self, character: Character, face: Face, pieces: Pieces | None, es: float,
                 points: ControlPoints | None = None) -> None:
        self.face, self.es = face, es
        self.v = character.vertices.astype(np.float64)
        drawn = np.zeros(0, np.int64)
        if pieces is not None and (pieces.eyes or pieces.mouth is not None):  # a decal face: what is drawn
            drawn = np.unique(np.concatenate([pieces.feature_vertices, pieces.on_skin]).astype(np.int64))
        mine = np.zeros(character.n_vertices, bool)
        mine[drawn] = True
        t = face.unwelded if face.unwelded is not None else face.triangles
        self.triangles = t[mine[t].all(axis=1)]
        labels = pieces.labels if pieces is not None else np.zeros(character.n_vertices, np.int64)
        self.piece = labels[self.triangles[:, 0]]
        all_t = np.asarray(character.triangles, np.int64)
        occluders = all_t[~mine[all_t].any(axis=1)]
        if len(self.triangles):  # only those whose front view can reach the drawn pieces (grown by 2 ES)
            local = face.to_frame(self.v)
            lo = local[self.triangles.ravel(), :2].min(0) - 2 * es
            hi = local[self.triangles.ravel(), :2].max(0) + 2 * es
            box = local[occluders][:, :, :2]
            occluders = occluders[((box.max(1) >= lo) & (box.min(1) <= hi)).all(axis=1)]
        self.occluders = occluders
        self.at_rest = self._shown(np.zeros_like(self.v))
        self.rest_area = self._front_area(np.zeros_like(self.v))
        self.poking = PokeThrough(face, self.v, self.triangles, self.piece, occluders, es, HIDDEN * es)
        self.names = {}  # piece label -> "the piece at <its nearest control point>", for the report
        for p in np.unique(self.piece):
            centre = self.v[np.unique(self.triangles[self.piece == p])].mean(0)
            near = "" if points is None else points.names[int(np.argmin(np.linalg.norm(
                self.v[points.vertices] - centre, axis=1)))]
            self.names[int(p)] = f"the drawn piece at {near}" if near else f"drawn piece {p}"

    def _shown(self, d: np.ndarray) -> np.ndarray:
        """(n_triangles, n_samples) bool: each sample of each drawn triangle in front of every occluder."""
        if not len(self.triangles):
            return np.zeros((0, len(SAMPLES)), bool)
        local = self.face.to_frame(self.v + d)
        points = np.einsum("sk,tkc->tsc", SAMPLES, local[self.triangles]).reshape(-1, 3)
        front = np.concatenate([skin_front_depth(points[i:i + 512, :2], local, self.occluders)
                                for i in range(0, len(points), 512)])
        return ~(front > points[:, 2] + HIDDEN * self.es).reshape(len(self.triangles), len(SAMPLES))

    def _front_area(self, d: np.ndarray) -> np.ndarray:
        """(n_triangles,) signed area of each drawn triangle seen from the front (face frame x, y)."""
        p = self.face.to_frame(self.v + d)[self.triangles][:, :, :2]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])

    def folding(self, d: np.ndarray) -> dict:
        """{piece label: share of its front-view area whose triangles turn over under displacements ``d``} (pieces
        with any)."""
        if not len(self.triangles):
            return {}
        rest = self.rest_area
        flipped = np.sign(self._front_area(d)) != np.sign(rest)
        out = {}
        for p in np.unique(self.piece):
            mine = self.piece == p
            area = np.abs(rest[mine])
            seen = area > FLAT * area.max(initial=0.0)
            if seen.any() and (flipped[mine] & seen).any():
                out[int(p)] = float(area[flipped[mine] & seen].sum() / area[seen].sum())
        return out

    def vanishing(self, d: np.ndarray) -> dict:
        """{piece label: share of it shown at rest and hidden under displacements ``d``} (pieces with any)."""
        lost = self.at_rest & ~self._shown(d)
        out = {}
        for p in np.unique(self.piece):
            rest = self.at_rest[self.piece == p].sum()
            if rest and lost[self.piece == p].any():
                out[int(p)] = float(lost[self.piece == p].sum() / rest)
        return out


def defects(drawn: Drawn, d: np.ndarray) -> list[str]:
    """The visible defects of displacements ``d`` (n_vertices, 3) on their own (see the module doc)."""
    out = []
    gone = _worst_by_name(drawn, drawn.vanishing(d), VANISHED)
    if gone:
        out.append("a drawn piece goes behind the skin or hair (" + ", ".join(
            f"{name}: {100 * s:.0f} %" for name, s in sorted(gone.items())) + ")")
    cut = _worst_by_name(drawn, drawn.poking(d), POKED)
    if cut:
        out.append("the skin shows through a drawn piece (" + ", ".join(
            f"{name}: {100 * s:.0f} % of a cross band of it" for name, s in sorted(cut.items())) + ")")
    turned = _worst_by_name(drawn, drawn.folding(d), FOLDED)
    if turned:
        out.append("a drawn piece folds over (" + ", ".join(
            f"{name}: {100 * s:.0f} % of its front-view area" for name, s in sorted(turned.items())) + ")")
    return out


def _worst_by_name(drawn: Drawn, share: dict, limit: float) -> dict[str, float]:
    """The largest share over ``limit`` of each drawn piece's name (the two strips of one drawn lip are one
    piece to the reader)."""
    worst: dict[str, float] = {}
    for p, s in share.items():
        if s > limit:
            worst[drawn.names[p]] = max(s, worst.get(drawn.names[p], 0.0))
    return worst


def compare(drawn: Drawn, mesh: np.ndarray, clone: np.ndarray, own: np.ndarray) -> dict:
    """The measures of the cloned and the character's own displacements (n_vertices, 3) and why the clone is
    worse ("worse": empty when it is not); see the module doc."""
    a, b = clone[mesh].ravel(), own[mesh].ravel()
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    cosine = float(a @ b) / (na * nb) if na > 0 and nb > 0 else 0.0
    worse, figures = [], {}
    checks = (("hidden", drawn.vanishing,
               "vanishing: {c:.0f} % of {name} goes behind the skin or hair (the expression's {o:.0f} %)"),
              ("folded", drawn.folding, "folding: {c:.0f} % of {name} folds over (the expression's {o:.0f} %)"),
              ("poked", drawn.poking,
               "poking through: the skin shows through {c:.0f} % of a cross band of {name} (the expression's "
               "{o:.0f} %)"))
    for key, measure, says in checks:
        of_clone, of_own = measure(clone), measure(own)
        figures[f"{key}_clone"] = round(max(of_clone.values(), default=0.0), 3)
        figures[f"{key}_own"] = round(max(of_own.values(), default=0.0), 3)
        more = {p: s - of_own.get(p, 0.0) for p, s in of_clone.items()}
        if more and max(more.values()) > VANISH_MORE:
            p = max(more, key=more.get)
            worse.append(says.format(c=100 * of_clone[p], o=100 * of_own.get(p, 0.0), name=drawn.names[p]))
    if cosine < AGREE:
        worse.append(f"moves otherwise: cosine {cosine:.2f} to the expression (< {AGREE})")
    return {"cosine": round(cosine, 3), "magnitude_ratio": round(na / nb, 3) if nb > 0 else None,
            **figures, "worse": worse}


def prefer_own(character: Character, face: Face, pieces: Pieces | None, keys: tuple[str, ...], dense: np.ndarray,
               es: float, points: ControlPoints | None = None, apply: bool = True) -> tuple[dict, dict]:
    """Each cloned shape of ``keys`` in ``dense`` (n, n_vertices, 3) checked (see the module doc); where the
    character has an expression for the channel and the clone is worse, the clone is replaced by it in place.
    Returns ({channel: {"used": "clone" or "<preset> (the character's own)", "why", measures}} for the channels
    with an expression, {channel: [defects]} for the others that are defective: an expression's own defects are
    the artist's, and a clone no worse than it is kept). ``points`` name the drawn pieces by their nearest.
    Without ``apply`` nothing is replaced: "used" is "clone" throughout and "why" says what would be used."""
    drawn = Drawn(character, face, pieces, es, points)
    used, defective = {}, {}
    for s, key in enumerate(keys):
        preset = CHANNEL_EXPRESSIONS.get(key)
        own = expression_deltas(character, preset) if preset else None
        clone = dense[s].astype(np.float64)
        if own is not None:
            m = compare(drawn, face.mesh, clone, own)
            if m["worse"] and apply:
                dense[s] = own.astype(dense.dtype)
                used[key] = {"used": f"{preset} (the character's own)",
                             "why": "the clone is worse: " + "; ".join(m["worse"]), **m}
                continue
            if m["worse"]:
                used[key] = {"used": "clone", "why": f"kept as asked, though worse than the character's own {preset}: "
                                                     + "; ".join(m["worse"]), **m}
                continue
            used[key] = {"used": "clone", "why": f"no worse than the character's own {preset}", **m}
            continue
        found = defects(drawn, dense[s].astype(np.float64))
        if found:
            defective[key] = found
    return used, defective
