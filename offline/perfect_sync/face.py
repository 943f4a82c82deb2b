"""Finding the face on any character: its mesh, its skin, its frame (symmetry plane, up, forward) and nose tip.

Where the face is, in order of evidence:

1. the character's own shapes: the layout mesh (glTF mesh) holding most of the
   vertices its morphs move;
2. the VRM humanoid ``head`` bone: the mesh holding most of the vertices
   weighted to it (weight >= 0.5);
3. otherwise the whole character.

The skin is the largest connected piece of that mesh (by area); eyes, teeth,
lashes are the other pieces. Pieces are connected **by position**, not by
vertex index: glTF stores one index per vertex for all its attributes, so a
surface is split into copies of a vertex wherever its UVs or normals change
(Godette's 630-vertex face mesh falls into 2507 index components, 17 pieces
once welded). Coincident vertices (within ``WELD`` of the character's size)
of one glTF primitive are one vertex (:func:`weld_map`); the face's triangles
are stored welded (onto each position's first copy), and whatever is
computed for a vertex is carried to its copies, which move identically. A
character without a glTF layout (OBJ, which indexes positions once) is not
welded: its coincident vertices are distinct pieces (ICT's tear film and eye
occlusion meet its lids there). The frame: characters are stored +Y up, facing
+Z (:mod:`facepuppet.runtime.model.character_parts`); the symmetry plane is fitted
to the skin by mirror ICP (reflect, match nearest points, refit the plane
from the matched pairs), up comes from the humanoid neck → head bones when
present, else +Y made orthogonal to the plane normal, and forward is their
cross product. The nose tip is the skin vertex farthest forward near the
symmetry plane; it must stand out of the forward-facing skin around it.

Refusals (:class:`FaceError`, naming the character and what is wrong): too
few vertices, no protruding nose near the symmetry plane (a cube, a sphere),
a skin that is not symmetric about the face's plane because the face is split
into several pieces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.model.character import Character, moving_vertices
from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.io.rig_import import FORWARD_TURNS, turn_about_y

MIN_SKIN_VERTICES = 60  # 47 control points need distinct vertices, with some room
NOSE_PROTRUSION = 0.04  # nose tip in front of its surroundings by this fraction of the skin width
BONE_UP_COS = 0.985  # the neck → head bone is taken as up within 10 degrees of +Y (anime necks lean)
WELD = 1e-6  # coincident glTF copies: within this fraction of the character's bounding-box diagonal
PIECE_OFFSET = 0.15  # the skin's centroid off the face's plane by this fraction of its width: split face


class FaceError(FacepuppetError, ValueError):
    """The character has no face the perfect-sync proposal can work on."""


@dataclass(frozen=True, eq=False)
class Face:
    """Where the face of a character is.

    Attributes
    ----------
    mesh : ndarray of shape (p,), int64, the face mesh's vertices (indices into the character)
    triangles : ndarray of shape (q, 3), int64, the face mesh's triangles (character indices)
    skin : ndarray of shape (s,), int64, the skin's vertices (character indices)
    frame : ndarray of shape (3, 3), float64, rows x (the character's left), y (up), z (forward)
    plane_offset : float, units, the symmetry plane is {p : frame[0] @ p = plane_offset}
    nose_tip : int, vertex index
    width : float, units, the skin's extent across the plane
    symmetry_error : float, median distance of the mirrored skin to itself / width
    evidence : str, how the face mesh was found ("shapes", "head bone", "whole character")
    origin : ndarray of shape (3,), float64, the face frame's origin in frame coordinates (see :meth:`to_frame`)
    weld : ndarray of shape (n_vertices,), int64, each vertex's first coincident copy (itself when none;
        :func:`weld_map`); ``triangles`` and ``skin`` hold these only, ``mesh`` every copy
    unwelded : ndarray of shape (q', 3), int64, or None: the face mesh's triangles as the character has them
        (every copy): where the artist's pieces meet along a seam of coincident vertices
    """

    mesh: np.ndarray
    triangles: np.ndarray
    skin: np.ndarray
    frame: np.ndarray
    plane_offset: float
    nose_tip: int
    width: float
    symmetry_error: float
    evidence: str
    origin: np.ndarray
    weld: np.ndarray | None = None
    unwelded: np.ndarray | None = None

    def to_frame(self, points: np.ndarray) -> np.ndarray:
        """Points (…, 3) in the face frame: origin on the plane at the nose tip's height and depth."""
        return np.asarray(points, np.float64) @ self.frame.T - self.origin



def weld_map(character: Character) -> np.ndarray:
    """(n_vertices,) int64: every vertex's first coincident copy in its glTF primitive (itself when it has none or
    the character has no layout); see the module doc."""
    n = character.n_vertices
    rep = np.arange(n, dtype=np.int64)
    lay = character.layout
    if lay is None or not n:
        return rep
    v = character.vertices.astype(np.float64)
    tol = WELD * max(float(np.linalg.norm(np.ptp(v, axis=0))), 1e-30)
    for first, count, *_ in lay.primitives:
        if count < 2:
            continue
        idx = np.arange(first, first + count)
        cell = np.round(v[idx] / tol).astype(np.int64)
        _, inverse = np.unique(cell, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        head = np.full(inverse.max() + 1, np.iinfo(np.int64).max)
        np.minimum.at(head, inverse, idx)
        rep[idx] = head[inverse]
    return rep


def welded_triangles(triangles: np.ndarray, weld: np.ndarray) -> np.ndarray:
    """``triangles`` (q, 3) onto the first copies of ``weld``, without those collapsed by it."""
    t = np.asarray(weld)[np.asarray(triangles, np.int64)]
    return t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]


def _mesh_of(character: Character, vertices: np.ndarray) -> np.ndarray | None:
    """Vertices of the layout mesh holding most of ``vertices``, or None without a layout."""
    lay = character.layout
    if lay is None or not len(vertices):
        return None
    mesh_of_vertex = np.full(character.n_vertices, -1, np.int64)
    for first, count, _, _, mesh, _ in lay.primitives:
        mesh_of_vertex[first:first + count] = mesh
    best = np.bincount(mesh_of_vertex[vertices][mesh_of_vertex[vertices] >= 0]).argmax()
    return np.flatnonzero(mesh_of_vertex == best)


def face_mesh(character: Character) -> tuple[np.ndarray, str]:
    """(vertices of the face mesh, the evidence used); see the module docstring."""
    moved = moving_vertices(character)
    if len(moved):
        mesh = _mesh_of(character, moved)
        return (np.arange(character.n_vertices) if mesh is None else mesh), "shapes"
    sk = character.skeleton
    if sk is not None and "head" in sk.bones:
        head = sk.bones["head"]
        w = np.where(sk.vertex_nodes == head, sk.vertex_weights, 0.0).sum(1)
        on_head = np.flatnonzero(w >= 0.5)
        mesh = _mesh_of(character, on_head)
        if mesh is not None:
            return mesh, "head bone"
        if len(on_head):
            return on_head, "head bone"
    return np.arange(character.n_vertices), "whole character"


def _areas(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)


def symmetry_plane(points: np.ndarray, normal: np.ndarray, iterations: int = 8) -> tuple[np.ndarray, float, float]:
    """Mirror ICP: (unit normal, offset, median mirrored distance) of the plane best mirroring ``points`` (n, 3)."""
    p = np.asarray(points, np.float64)
    tree = cKDTree(p)
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    d = float(np.median(p @ n))
    dist = np.inf
    for _ in range(iterations):
        mirrored = p - 2.0 * ((p @ n) - d)[:, None] * n
        dist_all, j = tree.query(mirrored)
        q = p[j]
        pair = p - q  # a point and its mirror partner: their difference lies along the normal
        far = np.linalg.norm(pair, axis=1) > 1e-9
        if not far.any():
            break
        signs = np.sign(pair[far] @ n)[:, None]
        n_new = (pair[far] * signs).sum(0)
        n_new /= np.linalg.norm(n_new)
        if n_new @ n < 0.9:  # no more than ~25 degrees from the stored frame's x
            break
        n = n_new
        d = float(np.median(0.5 * (p + q) @ n))
        dist = float(np.median(dist_all))
    return n, d, dist


def _turned(character: Character, degrees: float) -> Character:
    r = turn_about_y(degrees).astype(np.float32)
    return character.with_parts(vertices=character.vertices @ r.T, normals=None, skeleton=None)


#: the other ways an OBJ's face may look, and the turn about +Y that would bring each to +Z (import-rig --forward)
OTHER_FACINGS = tuple((axis, degrees) for axis, degrees in FORWARD_TURNS.items() if axis != "+z")
SHAPES_LEAN = 0.02  # the shapes' vertices' centre this fraction of the mesh's size off its centre shows the face
DETAIL_MARGIN = 1.25  # a static head's back with this many times the front's skin vertices is its face
SYMMETRY_SLACK = 0.005  # facings whose symmetry error is within this (face widths) of the best compete on the nose


def find_face(character: Character) -> Face:
    """The face of ``character`` (see the module docstring); FaceError when there is none.

    A character with no layout (an OBJ: glTF faces +Z by its spec, VRM 0.x is turned on import) may have
    been exported looking along another axis. With shapes, the way it looks is where its shapes move
    (their vertices' centre against the face mesh's); without, a face found facing +Z whose back half has
    clearly more skin vertices than its front is the back of a head (a face is where the detail is: the
    ICT head has 4 times as many in front, the demo head 1.6), and when no face is found facing +Z it is
    looked for facing -Z, +X and -X (the most symmetric facing whose nose stands out most). Either way a
    face looking elsewhere is refused saying so and how to import it turned."""
    try:
        face, _ = _find_face(character)
    except FaceError as exc:
        face, failure = None, exc
    if character.layout is not None:  # glTF faces +Z by its spec, a VRM 0.x is turned on import: no --forward
        if face is None:
            raise failure
        return face
    axis = None
    moved = moving_vertices(character)
    if len(moved):
        v = character.vertices.astype(np.float64)
        mesh = face.mesh if face is not None else face_mesh(character)[0]
        lean = v[moved].mean(0) - v[mesh].mean(0)
        options = {"+z": lean[2], "-z": -lean[2], "+x": lean[0], "-x": -lean[0]}
        best = max(options, key=options.get)
        if options[best] > SHAPES_LEAN * float(np.ptp(v[mesh], axis=0).max()):  # else the shapes say nothing
            axis = best
        if face is None and axis not in (None, "+z"):  # no face here: one must be there for the hint to help
            try:
                _find_face(_turned(character, dict(OTHER_FACINGS)[axis]))
            except FaceError:
                axis = None
    elif face is not None:  # a static head: a face has more detail (vertices) than the back of its head
        depth = character.vertices[face.skin].astype(np.float64) @ face.frame[2]
        middle = 0.5 * (depth.min() + depth.max())
        front, back = int((depth > middle).sum()), int((depth < middle).sum())
        if back > DETAIL_MARGIN * front:
            axis = "-z"
    else:
        found = []
        for name, degrees in OTHER_FACINGS:
            try:
                other, p = _find_face(_turned(character, degrees))
            except FaceError:
                continue
            found.append((name, other.symmetry_error, p))
        if found:
            best_symmetry = min(f[1] for f in found)
            axis = max((f for f in found if f[1] <= best_symmetry + SYMMETRY_SLACK), key=lambda f: f[2])[0]
    if axis is not None and axis != "+z":
        why = f"{failure}; " if face is None else f"{character.name}: its shapes move the side facing {axis}: "
        raise FaceError(f"{why}the face looks along {axis}, not +Z: import the OBJ again with "
                        f"import-rig --forward={axis} (characters are stored facing +Z, Y up)")
    if face is None:
        raise failure
    return face


def _find_face(character: Character) -> tuple[Face, float]:
    """The face facing +Z and how far its nose stands out (face widths); FaceError when there is none."""
    name = character.name
    mesh, evidence = face_mesh(character)
    keep = np.isin(character.triangles, mesh).all(axis=1)
    weld = weld_map(character)
    tris = welded_triangles(character.triangles[keep], weld)
    # every copy of the face mesh's vertices in triangles, and the first copies the welded triangles use
    copies = np.union1d(np.unique(character.triangles[keep]), np.unique(tris))
    v = character.vertices.astype(np.float64)
    if len(np.unique(tris)) < MIN_SKIN_VERTICES:
        raise FaceError(f"{name}: no recognisable face: the face mesh ({evidence}) has "
                        f"{len(np.unique(tris))} vertices in triangles, a face needs at least {MIN_SKIN_VERTICES}")
    _, labels = components(character.n_vertices, tris)
    area = np.bincount(labels[tris[:, 0]], weights=_areas(v, tris), minlength=labels.max() + 1)
    skin_label = int(np.argmax(area))
    skin = np.flatnonzero(labels == skin_label)
    skin = skin[np.isin(skin, tris)]
    if len(skin) < MIN_SKIN_VERTICES:
        raise FaceError(f"{name}: no recognisable face: its largest piece of skin has {len(skin)} vertices "
                        f"(at least {MIN_SKIN_VERTICES} needed)")
    # the face's plane, from every piece of the face mesh, then the skin's own
    used = np.unique(tris)
    n_all, d_all, _ = symmetry_plane(v[used], np.array([1.0, 0.0, 0.0]))
    width = float(np.ptp(v[skin] @ n_all))
    offset = abs(float(v[skin].mean(0) @ n_all) - d_all)
    if offset > PIECE_OFFSET * max(width, 1e-12):
        pieces = int((area > 0.25 * area.max()).sum())
        raise FaceError(f"{name}: the face is in several disconnected pieces: its largest piece of skin "
                        f"({len(skin)} vertices) lies {offset:.3g} {character.units} off the face's symmetry "
                        f"plane ({pieces} pieces of comparable size); join the skin into one piece")
    normal, d, dist = symmetry_plane(v[skin], n_all)
    up = np.array([0.0, 1.0, 0.0])
    sk = character.skeleton
    if sk is not None and "head" in sk.bones and "neck" in sk.bones:
        g = sk.global_transforms()
        bone_up = g[sk.bones["head"], :3, 3] - g[sk.bones["neck"], :3, 3]
        if np.linalg.norm(bone_up) > 1e-9 and bone_up @ up > BONE_UP_COS * np.linalg.norm(bone_up):
            up = bone_up / np.linalg.norm(bone_up)
    up = up - normal * (normal @ up)
    up /= np.linalg.norm(up)
    forward = np.cross(normal, up)
    frame = np.stack([normal, up, forward])
    local = v @ frame.T
    width = float(np.ptp(local[skin, 0]))
    # nose tip: the most forward skin vertex near the plane, among vertices facing forward
    normals = vertex_normals(character.vertices, tris.astype(np.uint32)).astype(np.float64) @ frame.T
    near = skin[(np.abs(local[skin, 0] - d) < 0.08 * width) & (normals[skin, 2] > 0.3)]
    if not len(near):
        raise FaceError(f"{name}: no recognisable face: no forward-facing skin on the symmetry plane")
    tip = int(near[np.argmax(local[near, 2])])
    front = skin[normals[skin, 2] > 0.3]
    around = front[np.hypot(local[front, 0] - d, local[front, 1] - local[tip, 1]) < 0.35 * width]
    around = around[np.hypot(local[around, 0] - d, local[around, 1] - local[tip, 1]) > 0.2 * width]
    if not len(around):
        raise FaceError(f"{name}: no recognisable face: no forward-facing skin around the nose tip")
    protrusion = float(local[tip, 2] - np.median(local[around, 2]))
    if protrusion < NOSE_PROTRUSION * width:
        raise FaceError(f"{name}: no recognisable face: no nose (the most forward point on the symmetry plane "
                        f"stands {protrusion:.3g} {character.units} in front of its surroundings, a face's nose "
                        f"at least {NOSE_PROTRUSION * width:.3g})")
    face = Face(mesh=copies, triangles=tris, skin=skin, frame=frame, plane_offset=d, nose_tip=tip,
                width=width, symmetry_error=dist / max(width, 1e-12), evidence=evidence,
                origin=np.array([d, local[tip, 1], local[tip, 2]]), weld=weld,
                unwelded=np.asarray(character.triangles[keep], np.int64))
    return face, protrusion / width
