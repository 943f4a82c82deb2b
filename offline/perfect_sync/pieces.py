"""The face's pieces that are not its skin: which lie on the skin, which are a decal face's eyes and mouth.

Many characters draw their features on separate pieces rather than in the
skin: Godette's eyes are stacked alpha decals (iris, pupil, highlights), a
lash-and-upper-lid strip and a brow quad, lying a few millimetres in front
of a 79-vertex skin that has no eye openings; her mouth is four collapsed
strips (closed line) in front of a skin with no mouth. The elastic clone
(:func:`~.transfer.clone_face`) moves the skin only, so on such a face it
moves nothing that the artist's shapes move. :func:`find_pieces` finds the
other pieces; the modules beside this one carry the clone onto them
(:mod:`.on_skin`, :mod:`.landmark_field`, :mod:`.drawn_eyes`,
:mod:`.eye_looks`):

* the pieces **on the skin** (lashes, tear films, blush decals): each vertex
  within ``ON_SKIN`` face widths of it;
* the **decal features**, where the skin has none: an eye is the largest
  forward piece (by its front-projected area) on each side above the nose
  tip where the skin has no opening, with every piece whose centre lies in
  its box; the mouth is the lowest forward piece near the symmetry plane
  below the nose tip, wider than tall, with every piece overlapping it,
  where the skin has no mouth opening;
* the decal mouth's **cut**, where its artist cut it (:func:`mouth_sides`): lip
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

from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.elastic.lip_line import boundary_loops
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.triangles import nearest_triangles, skin_front_depth

ON_SKIN = 0.06  # a piece lies on the skin when every vertex is within this many face widths of it
OPENING = 0.5  # a skin boundary loop within this many eye widths of a feature is its opening (a real eye/mouth)
DECAL_DEPTH = 0.6  # a decal eye's largest piece is no deeper than this fraction of its width
CORNER = 0.02  # a drawn eye's or mouth's corner: its vertices within this fraction of its width of either end


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
