"""The face's pieces that are not its skin, and how the cloned expressions carry onto them.

Many characters draw their features on separate pieces rather than in the
skin: Godette's eyes are stacked alpha decals (iris, pupil, highlights), a
lash-and-upper-lid strip and a brow quad, lying a few millimetres in front
of a 79-vertex skin that has no eye openings; her mouth is four collapsed
strips (closed line) in front of a skin with no mouth. The elastic clone
(:func:`~.transfer.clone_face`) moves the skin only, so on such a face it
moves nothing that the artist's shapes move. This module:

* **embeds** every other piece that lies on the skin (lashes, tear films,
  blush decals: each vertex within ``ON_SKIN`` face widths of it) on its
  nearest skin triangle: the piece's vertex takes the barycentric mix of
  the triangle's cloned displacements (:func:`embed`);
* finds **decal features** (:func:`decal_features`): an eye is the largest
  forward piece (by its front-projected area) on each side above the nose
  tip where the skin has no opening, with every piece whose centre lies in
  its box; the mouth is the lowest forward piece near the symmetry plane
  below the nose tip, wider than tall, with every piece overlapping it,
  where the skin has no mouth opening;
* moves decal features by a **landmark field** (:func:`feature_field`): the
  source's control points are placed on the target relative to the features
  (eye points by their place in the source eye's box of corners and lids,
  mouth points relative to the mouth corners and lip line, the others by
  the affine map these define), each control point's cloned displacement is
  scaled by its feature's size against the source's (an anime eye three
  times as tall as ICT's closes three times as far), and a thin-plate
  spline over the face's front plane interpolates them. The blinks' upper
  lid points are put onto the lower ones (the lids meet), and the field is
  **cut along the lip line**: a vertex above the mouth's line (a quadratic
  through the mouth pieces' vertices, with half of them above it) takes the field of the upper lip, one
  below it that of the lower lip and jaw, so the mouth opens between its
  lips even where they lie on one line at rest; likewise only the eye's own
  pieces follow the lid points (a brow piece just above the lashes does not),
  and an eye piece beyond the eye's box (the lashes above the upper lid)
  moves as the box's edge does;
* closes a decal eye in the blinks by a drawn eye's own rule rather than by
  the field (:func:`decal_blink`): the lids meet on the line joining the
  eye's corners (the ends of its outline, where they meet at rest), every
  vertex of the eye squashed onto that line to ``CLOSED`` of its rest height
  about it (a thin outline is left), and what lies inside the eye (iris,
  white) is covered rather than folded: it goes back along the line of sight
  behind the skin in front of it, by its stand-off plus ``HIDDEN`` of the
  eye's width. ``CLOSED`` and ``HIDDEN`` are chosen constants (5 %), not
  fitted to a character: Godette's blink cosine moves 0.72–0.74 for
  ``HIDDEN`` from 0 to 0.2. The outline above the line is lowered as a
  drawn stroke (:func:`closed_heights`): its edge nearest the line comes to
  ``CLOSED`` of its height, what lies beyond keeps up to ``LINE`` (10 %, a
  chosen constant: about the thickness of Godette's lash stroke at rest,
  0.012 of her 0.087 eye) of the eye's height and ``CLOSED`` of the rest.
  Squashed whole to 5 % her closed lash read as a faint broken hair-line in
  the take's side-by-side; lowering each column whole, keeping the lashes'
  tips, read as a line too but took her blink cosine to 0.67, below the
  goal (with ``LINE``: 0.73, 0.74);
* narrows a decal eye the same drawn way in every other shape that moves the
  lids (:func:`decal_narrow`; eyeSquint, browDown, cheekSquint; eyeWide
  opens it): toward its closed place, what lies above the corner line by the
  fraction of the blink's way that the source's shape lowers its upper lid
  points, what lies below by the fraction it raises the lower ones
  (:func:`lid_fractions`, measured on the source: ICT's eyeSquint 0.03 and
  0.42), the iris with it; a shape that moves no lid point leaves the eye.
  The landmark field squashed the lash outline into a V and pulled the iris
  (in the kit's take the blinks come with eyeSquint, eyeLookDown, browDown
  and cheekSquint at partial weights);
* gives a decal eye's looks to what lies inside it only (iris, white; the
  outline, the lashes and the skin stay): the character's own VRM look
  expressions' part on that eye where it has them (:func:`look_expressions`,
  :func:`look_keys`: Godette's ``look_up`` etc.; these come from her lookAt,
  not from cloning), otherwise the inside slides by the source's eye turn on
  a ball of half the eye's width, held inside the outline
  (:func:`decal_look_slide`);
* opens a decal mouth in the jaw's shapes (``JAW_OPENINGS`` of
  :mod:`.transfer`) by the lips' motion relative to each other: the skin
  around it does not move (no mouth hole, no lips), so the jaw's drop, the
  lip line's own motion (:func:`lip_line_motion`), is taken out and the
  mouth opens about its line. (Measured on Godette, mouth pieces only:
  cosine to her "ah" 0.24 with the jaw's drop, 0.48 without; projecting the
  motion onto the skin's tangent plane as well gave 0.47, so it is not done.
  Her artist also widens the mouth by half, which no source shape says.)
* cuts a decal mouth where its artist cut it (:func:`mouth_sides`): lip
  strips meeting on a seam part there, each strip whole with its lip, and a
  piece hidden inside the mouth above the line, the upper teeth, stays (it is
  fixed to the skull). On Godette her white strip had been lifted with the
  upper lip and her upper lip strip cut through along its lower edge; with
  both, her cloned jawOpen's cosine to her "ah" went from 0.47 to 0.74 over
  her face mesh. (Both rules were found by looking at where the clone and her
  artist differ; they are checked on the box head of ``tests/helpers`` too.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from facepuppet.runtime.character_parts import Expressions

from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.elastic.lip_line import boundary_loops
from facepuppet.offline.perfect_sync.face import Face

ON_SKIN = 0.06  # a piece lies on the skin when every vertex is within this many face widths of it
OPENING = 0.5  # a skin boundary loop within this many eye widths of a feature is its opening (a real eye/mouth)
DECAL_DEPTH = 0.6  # a decal eye's largest piece is no deeper than this fraction of its width
CLOSED = 0.05  # a decal blink leaves this fraction of each vertex's rest height about the closing line
CORNER = 0.02  # a drawn eye's corner: its vertices within this fraction of its width of its inner/outer end
STROKE = 0.05  # a drawn eye's outline column: its vertices within this fraction of the eye's width across
LINE = 0.1  # a closed drawn eye's outline keeps up to this fraction of the eye's height of its stroke
HIDDEN = 0.05  # a closed drawn eye's iris goes this fraction of the eye's width behind the skin (past its stand-off)
EYE_NAMES = ("eye_inner", "eye_outer", "lid_upper_inner", "lid_upper_outer", "lid_lower_inner", "lid_lower_outer")
MOUTH_NAMES = ("mouth_corner", "lip_upper", "lip_lower", "mouth_inner")  # prefixes
LOWER_JAW = ("lip_lower", "chin", "jaw_chin")  # prefixes of the points below the lip line


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray,
                                                                                                np.ndarray]:
    """Closest points of triangles (a, b, c) (m, 3) to points ``p`` (m, 3): (points (m, 3), barycentric (m, 3)).

    Ericson, Real-Time Collision Detection §5.1.5 (Voronoi regions of the vertices, edges and face).
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    denom = np.where(np.abs(denom) < 1e-30, 1e-30, denom)
    v, w = vb / denom, vc / denom  # inside the face
    bary = np.stack([1 - v - w, v, w], 1)

    def put(mask, u):
        bary[mask] = u[mask]

    safe = lambda x: np.where(np.abs(x) < 1e-30, 1e-30, x)  # noqa: E731
    # edges (checked before the vertices, which override them)
    t = d1 / safe(d1 - d3)
    put((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([1 - t, t, 0 * t], 1))
    t = d2 / safe(d2 - d6)
    put((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([1 - t, 0 * t, t], 1))
    t = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), np.stack([0 * t, 1 - t, t], 1))
    one = np.ones(len(p))
    zero = np.zeros(len(p))
    put((d1 <= 0) & (d2 <= 0), np.stack([one, zero, zero], 1))
    put((d3 >= 0) & (d4 <= d3), np.stack([zero, one, zero], 1))
    put((d6 >= 0) & (d5 <= d6), np.stack([zero, zero, one], 1))
    q = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return q, bary


def nearest_triangles(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                      k: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point its nearest triangle among the ``k`` with the nearest centroids: (triangle index (n,),
    barycentric (n, 3), distance (n,))."""
    p = np.asarray(points, np.float64)
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    k = min(k, len(t))
    _, cand = cKDTree(v[t].mean(1)).query(p, k=k)
    cand = np.asarray(cand).reshape(len(p), k)
    best_d = np.full(len(p), np.inf)
    best_t = np.zeros(len(p), np.int64)
    best_b = np.zeros((len(p), 3))
    for j in range(k):
        tri = t[cand[:, j]]
        q, bary = closest_on_triangles(p, v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]])
        d = np.linalg.norm(p - q, axis=1)
        better = d < best_d
        best_d[better], best_t[better], best_b[better] = d[better], cand[better, j], bary[better]
    return best_t, best_b, best_d


@dataclass(frozen=True, eq=False)
class Pieces:
    """The face mesh's pieces besides the skin.

    Attributes
    ----------
    labels : ndarray (n_vertices,), int64, piece label of every vertex of the character (-1: not the face mesh)
    skin_label : int
    on_skin : ndarray (p,), int64, vertices of the pieces lying on the skin (not feature pieces)
    eyes : dict "L"/"R" -> (vertices (int64), box (x0, x1, y0, y1) in the face frame): decal eyes
    mouth : (vertices (int64), (x_right, x_left), line (3,) quadratic y(x) in the face frame) or None
    mouth_below : ndarray (len(mouth vertices),), bool, which side of the lip line's cut each mouth vertex
        takes (:func:`mouth_sides`)
    upper_teeth : ndarray (t,), int64, the mouth's pieces inside it above the lip line (:func:`mouth_sides`)
    """

    labels: np.ndarray
    skin_label: int
    on_skin: np.ndarray
    eyes: dict
    mouth: tuple | None
    mouth_below: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    upper_teeth: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def feature_vertices(self) -> np.ndarray:
        parts = [m for m, _ in self.eyes.values()] + ([self.mouth[0]] if self.mouth is not None else [])
        return np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64)


def _area_2d(p: np.ndarray, t: np.ndarray) -> float:
    e1, e2 = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    return float(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())


def find_pieces(vertices: np.ndarray, face: Face, skin_triangles: np.ndarray, still: np.ndarray = ()) -> Pieces:
    """The face's pieces (see the module doc): which lie on the skin, which are decal eyes and mouth.

    ``still``: vertices of the eyeballs (:func:`~.transfer.eyeballs`), whose pieces are neither carried nor
    features. A decal eye is thin: its largest piece no deeper than ``DECAL_DEPTH`` of its width (Godette's
    iris 0.38; ICT's sclera, a ball in a socket of skin, 1.0).
    """
    v = np.asarray(vertices, np.float64)
    tris = face.triangles
    n = len(v)
    _, labels = components(n, tris)  # the face's triangles are welded: a seam's copies take their first's piece
    if face.weld is not None:
        labels = labels[face.weld]
    labels = np.where(np.isin(np.arange(n), face.mesh), labels, -1)
    skin_label = int(labels[face.skin[0]])
    local = face.to_frame(v)
    width = face.width
    held = set(np.unique(labels[np.asarray(still, np.int64)]).tolist()) if len(still) else set()
    others = [lab for lab in np.unique(labels[face.mesh]) if lab != skin_label]
    members = {lab: np.flatnonzero(labels == lab) for lab in others}
    on_skin = []
    if len(skin_triangles):
        for lab in others:
            _, _, dist = nearest_triangles(v[members[lab]], v, skin_triangles)
            if dist.max() < ON_SKIN * width:
                on_skin.append(lab)
    loops = [local[loop].mean(0) for loop in boundary_loops(n, skin_triangles)] if len(skin_triangles) else []
    info = {}
    for lab in on_skin:
        m = members[lab]
        t = tris[np.isin(tris, m).all(axis=1)]
        p = local[m]
        info[lab] = {"centre": 0.5 * (p.min(0) + p.max(0)), "lo": p.min(0), "hi": p.max(0),
                     "area": _area_2d(local, t) if len(t) else 0.0}

    def opening_near(centre, size):
        return any(np.linalg.norm(c[:2] - centre[:2]) < OPENING * size for c in loops)

    eyes = {}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        cand = [lab for lab, i in info.items() if sign * i["centre"][0] > 0.1 * width and i["centre"][1] > 0
                and sign * i["centre"][0] < 0.45 * width and i["area"] > 0]
        if not cand:
            continue
        core = max(cand, key=lambda lab: info[lab]["area"])
        lo, hi = info[core]["lo"], info[core]["hi"]
        size = float(hi[0] - lo[0])
        if core in held or hi[2] - lo[2] > DECAL_DEPTH * size or opening_near(info[core]["centre"], size):
            continue  # the skin has its own eye here: the elastic clone and the eyeballs handle it
        group = [lab for lab in cand if lab not in held and np.all(info[lab]["centre"][:2] >= lo[:2])
                 and np.all(info[lab]["centre"][:2] <= hi[:2])]
        eyes[side] = (np.concatenate([members[lab] for lab in group]),
                      (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])))
    mouth = None
    cand = [lab for lab, i in info.items() if lab not in held and abs(i["centre"][0]) < 0.05 * width
            and i["centre"][1] < 0 and (i["hi"][0] - i["lo"][0]) > (i["hi"][1] - i["lo"][1])]
    if cand:
        low = min(cand, key=lambda lab: info[lab]["centre"][1])
        lo, hi = info[low]["lo"], info[low]["hi"]
        pad = 0.25 * float(hi[0] - lo[0])  # strips stacked a hair apart at a closed mouth
        group = [lab for lab in cand if info[lab]["lo"][1] <= hi[1] + pad and info[lab]["hi"][1] >= lo[1] - pad]
        m = np.concatenate([members[lab] for lab in group])
        p = local[m]
        size = float(np.ptp(p[:, 0]))
        if not opening_near(0.5 * (p.min(0) + p.max(0)), size):
            line = np.polyfit(p[:, 0], p[:, 1], 2 if len(np.unique(np.round(p[:, 0], 9))) > 2 else 0)
            line = np.concatenate([np.zeros(3 - len(line)), line])
            line[2] += float(np.median(p[:, 1] - np.polyval(line, p[:, 0])))  # half the mouth above, half below
            mouth = (m, (float(p[:, 0].min()), float(p[:, 0].max())), line)
    mouth_below, upper_teeth = (mouth_sides(mouth, labels, local, face, skin_triangles) if mouth is not None
                                else (np.zeros(0, bool), np.zeros(0, np.int64)))
    features = set()
    for m, _ in eyes.values():
        features.update(np.unique(labels[m]).tolist())
    if mouth is not None:
        features.update(np.unique(labels[mouth[0]]).tolist())
    rest = [members[lab] for lab in on_skin if lab not in features and lab not in held]
    return Pieces(labels=labels, skin_label=skin_label,
                  on_skin=np.concatenate(rest) if rest else np.zeros(0, np.int64), eyes=eyes, mouth=mouth,
                  mouth_below=mouth_below, upper_teeth=upper_teeth)


def mouth_sides(mouth: tuple, labels: np.ndarray, local: np.ndarray, face: Face,
                skin_triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which side of the lip line's cut each vertex of a decal mouth takes, and which of its pieces are the
    upper teeth.

    * A vertex below the line takes the lower lip's field, one above it the upper lip's; but where the artist
      drew the lips as strips meeting along a seam (coincident copies of one place, each in its own strip:
      Godette's upper lip's lower edge is her lower lip's upper edge), the seam is where the mouth opens, and
      each copy goes with its own strip: with the side its strip's other vertices lie on (when they lie on one
      side), wherever the quadratic line passes between the copies. At the mouth's corners (within ``CORNER``
      of its width of either end) the lips meet: there the copies stay together.
    * A piece (welded) lying wholly above the line and hidden at rest, more than half of its vertices behind
      another surface of the face (the skin or the lips) along the line of sight, is inside the mouth above
      it: the upper teeth, fixed to the skull, which no expression moves (Godette's white strip: the clone
      lifted it with the upper lip, 25 % of her cloned jawOpen's motion, which her artist's "ah" holds).

    Returns
    -------
    below : ndarray (len(mouth[0]),), bool
    upper_teeth : ndarray (t,), int64, vertices
    """
    m, (x0, x1), line = mouth
    above = local[m, 1] - np.polyval(line, local[m, 0])
    below = above < 0
    if face.weld is not None and face.unwelded is not None and len(face.unwelded):
        _, strip = components(len(local), face.unwelded)  # the pieces as drawn, before welding
        rep = face.weld[m]
        # a seam copy: its place (welded vertex) is shared by vertices of two strips or more
        places, n_strips = np.unique(np.unique(np.column_stack([rep, strip[m]]), axis=0)[:, 0], return_counts=True)
        seam = np.isin(rep, places[n_strips > 1])
        for st in np.unique(strip[m[seam]]):
            mine = strip[m] == st
            rest = below[mine & ~seam]
            if len(rest) and (rest.all() or not rest.any()):
                below[mine & seam] = rest[0]
        x = local[m, 0]
        corner = seam & ((x - x0 < CORNER * (x1 - x0)) | (x1 - x < CORNER * (x1 - x0)))
        side = dict(zip(m.tolist(), below.tolist()))
        below[corner] = [side.get(int(r), b) for r, b in zip(rep[corner], below[corner])]
    teeth = []
    tris = face.triangles
    for lab in np.unique(labels[m]):
        piece = np.flatnonzero(labels == lab)
        if not (local[piece, 1] > np.polyval(line, local[piece, 0])).all():
            continue
        others = tris[~np.isin(tris, piece).any(axis=1)]
        front = skin_front_depth(local[piece, :2], local, np.vstack([others, skin_triangles]))
        if (np.nan_to_num(front - local[piece, 2], nan=-1.0) > 0).mean() > 0.5:
            teeth.append(piece)
    return below, (np.concatenate(teeth) if teeth else np.zeros(0, np.int64))


def embed(vertices: np.ndarray, pieces: np.ndarray, skin_triangles: np.ndarray,
          dense: np.ndarray) -> np.ndarray:
    """Displacements (n_shapes, p, 3) of the ``pieces`` vertices carried by their nearest skin triangles'
    (barycentric mix of ``dense`` (n_shapes, n_vertices, 3))."""
    v = np.asarray(vertices, np.float64)
    tri, bary, _ = nearest_triangles(v[pieces], v, skin_triangles)
    corners = skin_triangles[tri]  # (p, 3)
    return np.einsum("pk,spkc->spc", bary, dense[:, corners])


def _prefixed(name: str, prefixes: tuple) -> bool:
    return any(name == p or name.startswith(p + "_") for p in prefixes)


def feature_places(pieces: Pieces, source_positions: np.ndarray, names: tuple) -> tuple[np.ndarray, np.ndarray,
                                                                                           np.ndarray]:
    """Where the source's control points lie on a decal face, relative to its features (see the module doc):
    (places (n_c, 2) x, y in the face frame; scales (n_c, 3) of their displacements; placed by a feature (n_c,)
    bool, the others by the affine map these define). Places are NaN when fewer than 3 are placed."""
    src = np.asarray(source_positions, np.float64)
    idx = {n: i for i, n in enumerate(names)}
    n_c = len(names)
    pos = np.full((n_c, 2), np.nan)  # target places in the face frame (x, y)
    scale = np.full((n_c, 3), np.nan)
    for side, (_, (x0, x1, y0, y1)) in pieces.eyes.items():
        sign = 1.0 if side == "L" else -1.0
        need = [f"{n}_{side}" for n in EYE_NAMES]
        if not all(n in idx for n in need):
            continue
        s_in, s_out = src[idx[f"eye_inner_{side}"]], src[idx[f"eye_outer_{side}"]]
        s_low = np.mean([src[idx[f"lid_lower_{p}_{side}"]][1] for p in ("inner", "outer")])
        s_up = np.mean([src[idx[f"lid_upper_{p}_{side}"]][1] for p in ("inner", "outer")])
        t_in, t_out = (x0, x1) if sign > 0 else (x1, x0)
        sx = abs(t_out - t_in) / max(abs(s_out[0] - s_in[0]), 1e-12)
        sy = (y1 - y0) / max(s_up - s_low, 1e-12)
        for name in names:
            if not name.endswith("_" + side) or not (_prefixed(name[:-2], EYE_NAMES) or name.startswith("brow")):
                continue
            p = src[idx[name]]
            u = (p[0] - s_in[0]) / (s_out[0] - s_in[0])
            if name.startswith("brow"):  # above the upper lid by the source's gap, in the eye's width scale
                y = y1 + (p[1] - s_up) * sx
            else:
                y = y0 + (p[1] - s_low) / (s_up - s_low) * (y1 - y0)
            pos[idx[name]] = (t_in + u * (t_out - t_in), y)
            scale[idx[name]] = (sx, sy if not name.startswith("brow") else sx, sx)
    if pieces.mouth is not None and all(n in idx for n in ("mouth_corner_L", "mouth_corner_R",
                                                          "lip_upper_inner", "lip_lower_inner")):
        _, (xr, xl), line = pieces.mouth
        s_r, s_l = src[idx["mouth_corner_R"]], src[idx["mouth_corner_L"]]
        s_line = 0.5 * (src[idx["lip_upper_inner"]][1] + src[idx["lip_lower_inner"]][1])
        sm = (xl - xr) / max(s_l[0] - s_r[0], 1e-12)
        for name in names:
            if not (_prefixed(name, MOUTH_NAMES) or _prefixed(name, LOWER_JAW)):
                continue
            p = src[idx[name]]
            x = xr + (p[0] - s_r[0]) / (s_l[0] - s_r[0]) * (xl - xr)
            pos[idx[name]] = (x, np.polyval(line, x) + (p[1] - s_line) * sm)
            scale[idx[name]] = sm
    placed = ~np.isnan(pos[:, 0])
    if placed.sum() < 3:
        return pos, scale, placed
    # the others by the affine map the placed ones define, at their mean scale
    a = np.column_stack([src[placed, :2], np.ones(placed.sum())])
    affine = np.linalg.lstsq(a, pos[placed], rcond=None)[0]
    rest = ~placed
    pos[rest] = np.column_stack([src[rest, :2], np.ones(rest.sum())]) @ affine
    scale[rest] = float(np.sqrt(abs(np.linalg.det(affine[:2]))))
    return pos, scale, placed


def feature_field(pieces: Pieces, face: Face, vertices: np.ndarray, source_positions: np.ndarray,
                  names: tuple, params: np.ndarray, shape_names: tuple, targets: np.ndarray,
                  places: np.ndarray | None = None, below: np.ndarray | None = None) -> np.ndarray:
    """Displacements (n_shapes, len(targets), 3) in world axes of the ``targets`` vertices by the landmark field
    (see the module doc). ``params``: the source's (n_shapes, n_c, 3), source units and axes (+Y up, +Z
    forward); ``source_positions`` (n_c, 3). ``places`` (len(targets), 2), when given, are where (x, y in the
    face frame) the field is evaluated instead of at the targets, and ``below`` (bool) which side of the lip
    line's cut each takes instead of the side it lies on."""
    prm = np.asarray(params, np.float64)
    idx = {n: i for i, n in enumerate(names)}
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    n_c = len(names)
    lower = np.array([_prefixed(n, LOWER_JAW) for n in names])
    upper_lip = np.array([_prefixed(n, ("lip_upper",)) for n in names])
    line = pieces.mouth[2] if pieces.mouth is not None and all(n in idx for n in (
        "mouth_corner_L", "mouth_corner_R", "lip_upper_inner", "lip_lower_inner")) else None
    pos, scale, placed = feature_places(pieces, source_positions, names)
    if placed.sum() < 3:
        return np.zeros((len(prm), len(targets), 3))
    disp = prm * scale[None]  # (s, n_c, 3) in the source's axes = the face frame's
    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        if key not in shape_names or side not in pieces.eyes:
            continue
        s = shape_names.index(key)
        for part in ("inner", "outer"):
            i, j = idx[f"lid_upper_{part}_{side}"], idx[f"lid_lower_{part}_{side}"]
            gap = pos[i, 1] - pos[j, 1]
            disp[s, i, 1] = pos[j, 1] + disp[s, j, 1] + CLOSED * gap - pos[i, 1]
    tgt = local[np.asarray(targets, np.int64)]
    if places is not None:
        tgt = np.column_stack([np.asarray(places, np.float64)[:, :2], tgt[:, 2]])
    out = np.zeros((len(prm), len(tgt), 3))
    flat = disp.transpose(1, 0, 2).reshape(n_c, -1)
    if below is None:
        below = np.zeros(len(tgt), bool) if line is None else tgt[:, 1] < np.polyval(line, tgt[:, 0])
        if line is not None and len(pieces.mouth_below):  # the mouth's vertices: the side mouth_sides gave them
            side = dict(zip(pieces.mouth[0].tolist(), pieces.mouth_below.tolist()))
            below = np.array([side.get(int(t), b) for t, b in zip(np.asarray(targets).tolist(), below)], bool)
    eye_members = [m for m, _ in pieces.eyes.values()]
    in_eye = np.isin(targets, np.concatenate(eye_members)) if eye_members else np.zeros(len(tgt), bool)
    lids = np.array([n.startswith("lid_") for n in names])
    for is_below in (False, True):
        for inside in (False, True):
            where = (below == is_below) & (in_eye == inside)
            if not where.any():
                continue
            keep = ~(upper_lip if is_below else lower) if line is not None else np.ones(n_c, bool)
            if not inside:
                keep &= ~lids  # the lids are the eye's moving edge: what is not the eye (a brow) does not follow them
            at = tgt[where, :2].copy()
            if inside:  # an eye piece beyond the lid points (the lashes above the upper lid) moves as the lid
                for m, (x0, x1, y0, y1) in pieces.eyes.values():
                    mine = np.isin(np.asarray(targets)[where], m)
                    at[mine] = np.clip(at[mine], [x0, y0], [x1, y1])
            rbf = RBFInterpolator(pos[keep], flat[keep], kernel="thin_plate_spline", smoothing=0.0, degree=1)
            out[:, where] = rbf(at).reshape(where.sum(), len(prm), 3).transpose(1, 0, 2)
    return out @ face.frame  # face-frame axes back to world


def eye_inside(pieces: Pieces, local: np.ndarray, side: str) -> np.ndarray:
    """The vertices of the ``side`` decal eye's pieces lying wholly within its largest piece's box (iris, pupil,
    highlights, the eye's white; not the outline and lashes reaching beyond it). ``local``: face-frame positions."""
    members, (x0, x1, y0, y1) = pieces.eyes[side]
    labels = pieces.labels[members]
    p = local[members]
    within = (p[:, 0] >= x0 - 1e-9) & (p[:, 0] <= x1 + 1e-9) & (p[:, 1] >= y0 - 1e-9) & (p[:, 1] <= y1 + 1e-9)
    inside = [lab for lab in np.unique(labels) if within[labels == lab].all()]
    return members[np.isin(labels, inside)]


def drawn_corners(pieces: Pieces, local: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(inner, outer) corner (x, y) in the face frame of the ``side`` decal eye: the mean place of its pieces'
    vertices within ``CORNER`` of its width from its innermost / outermost point (the ends of its outline)."""
    members, _ = pieces.eyes[side]
    p = local[members, :2]
    sign = 1.0 if side == "L" else -1.0
    across = sign * p[:, 0]
    reach = CORNER * float(np.ptp(across))
    inner = p[across <= across.min() + reach].mean(0)
    outer = p[across >= across.max() - reach].mean(0)
    return inner, outer


def skin_front_depth(xy: np.ndarray, local: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Depth (face-frame z) of the frontmost surface of ``triangles`` on the line of sight (along the face's
    forward) through each of the points ``xy`` (m, 2), NaN where none crosses it; ``local`` the vertices in the
    face frame."""
    out = np.full(len(xy), -np.inf)
    for start in range(0, len(triangles), 4096):
        t = local[triangles[start:start + 4096]]  # (k, 3, 3)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        ok = np.abs(det) > 1e-18
        a, b, c, det = a[ok], b[ok], c[ok], det[ok]
        px, py = xy[:, None, 0] - a[None, :, 0], xy[:, None, 1] - a[None, :, 1]
        u = (px * (c[:, 1] - a[:, 1]) - py * (c[:, 0] - a[:, 0])) / det
        w = (py * (b[:, 0] - a[:, 0]) - px * (b[:, 1] - a[:, 1])) / det
        hit = (u >= -1e-9) & (w >= -1e-9) & (u + w <= 1 + 1e-9)
        z = a[None, :, 2] + u * (b[:, 2] - a[:, 2]) + w * (c[:, 2] - a[:, 2])
        out = np.maximum(out, np.where(hit, z, -np.inf).max(axis=1, initial=-np.inf))
    return np.where(np.isfinite(out), out, np.nan)


def _above_corner_line(pieces: Pieces, local: np.ndarray, side: str) -> np.ndarray:
    """Height (face-frame y) of each vertex of the ``side`` decal eye's pieces above the line through its drawn
    corners (:func:`drawn_corners`); negative below it."""
    members, _ = pieces.eyes[side]
    inner, outer = drawn_corners(pieces, local, side)
    slope = (outer[1] - inner[1]) / (outer[0] - inner[0]) if abs(outer[0] - inner[0]) > 1e-12 else 0.0
    return local[members, 1] - (inner[1] + slope * (local[members, 0] - inner[0]))


def closed_heights(pieces: Pieces, local: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(rest, closed) height of each vertex of the ``side`` decal eye's pieces above the line through its drawn
    corners (:func:`_above_corner_line`; negative below it). Closed, what lies inside the eye (:func:`eye_inside`)
    keeps ``CLOSED`` of its height, and so does what of the outline lies below the line (a lash tail at the
    outer corner); the outline above it comes down onto the line as a drawn stroke: in each column (its
    vertices above the line within ``STROKE`` of the eye's width across) the edge nearest the line keeps
    ``CLOSED`` of its height, what lies beyond that edge keeps up to ``LINE`` of the eye's height of its distance
    from it and ``CLOSED`` of the rest (the lashes' tips), so that the closed eye is a visible line rather than a
    hair-line (Godette: her lash strip squashed whole to 5 % read as nothing in the take's side-by-side)."""
    members, (_, _, y0, y1) = pieces.eyes[side]
    rest = _above_corner_line(pieces, local, side)
    closed = CLOSED * rest
    outline = ~np.isin(members, eye_inside(pieces, local, side))
    x = local[members, 0]
    reach = STROKE * float(np.ptp(x))
    keep = LINE * (y1 - y0)
    for k in np.flatnonzero(outline & (rest > 0)):
        col = outline & (np.abs(x - x[k]) <= reach) & (rest > 0)
        edge = float(rest[col].min())
        beyond = rest[k] - edge
        closed[k] = CLOSED * edge + min(beyond, keep) + CLOSED * max(beyond - keep, 0.0)
    return rest, closed


def decal_blink(pieces: Pieces, face: Face, vertices: np.ndarray, skin_triangles: np.ndarray,
                side: str) -> tuple[np.ndarray, np.ndarray]:
    """The closed drawn eye of ``side``: (its pieces' vertices, their displacements (m, 3) in world axes).

    A drawn eye's lids meet on the curve joining its corners, where they meet at rest already (a closed eye
    is drawn as the line from corner to corner): every vertex of the eye's pieces comes toward the line through
    the corners (:func:`drawn_corners`) along the face's up, to its closed height (:func:`closed_heights`), the
    upper part down, the lower part up, the outline so keeping a line. What lies inside the
    eye (:func:`eye_inside`: the iris and the eye's white) is covered instead, not folded: it keeps its shape
    and goes back along the line of sight behind the skin in front of it (:func:`skin_front_depth`), by its
    stand-off plus ``HIDDEN`` of the eye's width."""
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    members, (x0, x1, _, _) = pieces.eyes[side]
    rest, closed = closed_heights(pieces, local, side)
    d = np.zeros((len(members), 3))
    d[:, 1] = closed - rest
    hide = np.isin(members, eye_inside(pieces, local, side))
    d[hide, 1] = 0.0  # covered, not folded: what lies inside the eye keeps its shape and goes behind the skin
    if hide.any() and len(skin_triangles):
        at = local[members[hide]]
        front = skin_front_depth(at[:, :2], local, skin_triangles)
        back = np.where(np.isnan(front), 0.0, np.maximum(at[:, 2] - front, 0.0) + HIDDEN * abs(x1 - x0))
        d[hide, 2] -= back
    return members, d @ face.frame


def lip_line_motion(pieces: Pieces, face: Face, vertices: np.ndarray, source_positions: np.ndarray,
                    names: tuple, params: np.ndarray, shape_names: tuple) -> np.ndarray:
    """The decal mouth's line's own motion under each vertex of the mouth: (n_shapes, m, 3) in world axes, the
    mean of the upper lip's field and the lower lip's (:func:`feature_field`) on the lip line at the vertex's
    place across the face. What a vertex's field adds to it is the lips' motion relative to each other."""
    m = pieces.mouth[0]
    x = face.to_frame(np.asarray(vertices, np.float64)[m])[:, 0]
    on = np.column_stack([x, np.polyval(pieces.mouth[2], x)])
    args = (pieces, face, vertices, source_positions, names, params, shape_names, m, on)
    return 0.5 * (feature_field(*args, below=np.zeros(len(m), bool)) + feature_field(*args, below=np.ones(len(m),
                                                                                                           bool)))


def lid_fractions(source_positions: np.ndarray, names: tuple, params: np.ndarray, shape_names: tuple,
                     key: str, side: str) -> tuple[float, float]:
    """(upper, lower): how far the source's shape ``key`` brings the ``side`` eye's upper lid down and its lower
    lid up, each as a fraction of the gap its blink closes (the mean over the inner and outer lid points; each in
    [-1, 1], negative where the shape opens the eye (eyeWide); (0, 0) without the lid points or the blink).
    Measured on the source's parameters, not a chosen constant: ICT's eyeSquint raises the lower lid 0.42 of the
    blink's closure and lowers the upper 0.03; its browDown lowers the upper lid 0.14, its cheekSquint raises
    the lower lid 0.45."""
    idx = {n: i for i, n in enumerate(names)}
    blink = {"L": "eyeBlinkLeft", "R": "eyeBlinkRight"}[side]
    if key not in shape_names or blink not in shape_names:
        return 0.0, 0.0
    prm = np.asarray(params, np.float64)
    sq, bl = prm[shape_names.index(key)], prm[shape_names.index(blink)]
    up, low = [], []
    for part in ("inner", "outer"):
        i, j = idx.get(f"lid_upper_{part}_{side}"), idx.get(f"lid_lower_{part}_{side}")
        if i is None or j is None:
            continue
        closure = bl[j, 1] - bl[i, 1]  # the blink's closing of the gap (upper down, lower up)
        if closure <= 1e-12:
            continue
        up.append(-sq[i, 1] / closure)
        low.append(sq[j, 1] / closure)
    if not up:
        return 0.0, 0.0
    return float(np.clip(np.mean(up), -1.0, 1.0)), float(np.clip(np.mean(low), -1.0, 1.0))


def decal_narrow(pieces: Pieces, face: Face, vertices: np.ndarray, side: str, upper: float,
                 lower: float) -> tuple[np.ndarray, np.ndarray]:
    """The narrowed (or, by negative fractions, opened) drawn eye of ``side``: (its pieces' vertices, their
    displacements (m, 3) in world axes). A drawn eye narrows the way it closes (:func:`decal_blink`): toward its
    closed place (:func:`closed_heights`) along the face's up, what lies above the corner line by ``upper`` of
    the blink's way there, what lies below by ``lower`` (:func:`lid_fractions`), the iris and white with it (a
    squint does not hide them); the outline's tail below the line stays (it is the upper stroke's)."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    members, _ = pieces.eyes[side]
    rest, closed = closed_heights(pieces, local, side)
    d = np.zeros((len(members), 3))
    d[:, 1] = (closed - rest) * np.where(rest > 0, upper, lower)
    tail = (rest < 0) & ~np.isin(members, eye_inside(pieces, local, side))
    d[tail] = 0.0  # the upper stroke's tail below the corner: the lower lid's rise moves what lies inside the eye
    return members, d @ face.frame


#: The VRM 0.x look presets whose shapes give a decal eye's looks where a character has them.
LOOK_PRESETS = ("LookUp", "LookDown", "LookLeft", "LookRight")


def look_expressions(expressions: Expressions | None, delta_offsets: np.ndarray, delta_indices: np.ndarray,
                     delta_positions: np.ndarray, n_vertices: int) -> dict:
    """{preset: dense displacements (n_vertices, 3) float64} of the character's own VRM look expressions
    (``expressions``: its :class:`~facepuppet.runtime.character_parts.Expressions`, or None), each its binds'
    weighted sum of the character's sparse shape deltas; an expression that binds no shape is left out."""
    out: dict = {}
    if expressions is None:
        return out
    for e, preset in enumerate(expressions.presets):
        if preset not in LOOK_PRESETS or preset in out:
            continue
        shapes, weights = expressions.binds(e)
        d = np.zeros((n_vertices, 3))
        for s, w in zip(shapes.astype(np.int64), weights):
            sl = slice(int(delta_offsets[s]), int(delta_offsets[s + 1]))
            np.add.at(d, delta_indices[sl].astype(np.int64), float(w) * delta_positions[sl].astype(np.float64))
        if np.abs(d).max(initial=0.0) > 0:
            out[preset] = d
    return out


def look_keys(looks: dict, pieces: Pieces, face: Face, vertices: np.ndarray) -> dict:
    """{(ARKit eye-look key, side): (preset, the ``side`` eye's inside vertices)} for the character's own look
    expressions ``looks`` (:func:`look_expressions`): which ARKit look of which eye each is, told by where it moves
    that eye's iris (the mean motion of :func:`eye_inside` in the face frame), not by its name: a horizontal one
    toward +x (the character's left) is eyeLookOutLeft on the left eye and eyeLookInRight on the right one, an
    upward one eyeLookUp. Of two giving one key, the one moving the iris farther."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    best: dict = {}
    for preset, d in looks.items():
        motion = d @ face.frame.T  # face-frame axes
        for side in pieces.eyes:
            inside = eye_inside(pieces, local, side)
            if not len(inside):
                continue
            mean = motion[inside].mean(0)
            if preset in ("LookUp", "LookDown"):
                amount, key = abs(mean[1]), "eyeLookUp" if mean[1] > 0 else "eyeLookDown"
            else:
                toward_left = mean[0] > 0
                amount = abs(mean[0])
                key = ("eyeLookOut" if toward_left else "eyeLookIn") if side == "L" else (
                    "eyeLookIn" if toward_left else "eyeLookOut")
            if amount <= 1e-9:
                continue
            key += "Left" if side == "L" else "Right"
            if (key, side) not in best or amount > best[(key, side)][0]:
                best[(key, side)] = (amount, preset, inside)
    return {k: (preset, inside) for k, (_, preset, inside) in best.items()}


def decal_look_slide(pieces: Pieces, face: Face, vertices: np.ndarray, side: str, axis: int,
                     slide: float) -> tuple[np.ndarray, np.ndarray]:
    """A drawn eye's look where the character has no look expression: (the ``side`` eye's inside vertices
    (:func:`eye_inside`), their displacement (m, 3) in world axes). They slide together by ``slide`` along the
    face frame's ``axis`` (0 across, + toward the character's left; 1 up), held inside the outline (the eye's other
    pieces): across, the iris stays between the outline's ends; up, its top stays below the outline's top, and
    down it goes no farther than up may (a drawn eye's outline is often its upper lid only). An eye with no outline
    piece slides unheld."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    members, _ = pieces.eyes[side]
    inside = eye_inside(pieces, local, side)
    outline = members[~np.isin(members, inside)]
    if len(outline) and len(inside):
        p, o = local[inside, axis], local[outline, axis]
        if axis == 0:
            room_low, room_high = max(p.min() - o.min(), 0.0), max(o.max() - p.max(), 0.0)
        else:
            room_high = max(o.max() - p.max(), 0.0)
            room_low = room_high
        slide = float(np.clip(slide, -room_low, room_high))
    d = np.zeros((len(inside), 3))
    d[:, axis] = slide
    return inside, d @ face.frame
