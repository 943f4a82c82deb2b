"""Control points (handles) of the elastic face model and where they come from.

Yano & Harada (2009) drive the skin from about 47 feature points in the
spirit of MPEG-4, denser around the eyes and mouth. Here a control-point set
is an ordered list of (name, vertex index); names carry the roles the method
needs: ``nose_tip`` and ``forehead`` (fixed-region rule, §4) and
``eye_inner_L`` / ``eye_inner_R`` (FAPU, §5).

File format (JSON, also used for cloning correspondences: the target's file
uses the source's names)::

    {"format": "facepuppet-control-points", "version": 1,
     "points": [{"name": "nose_tip", "vertex": 1234}, ...]}

Sources: :func:`ict_control_points` (40 of the 68 Multi-PIE landmarks of the ICT head
plus 7 added points), :func:`propose_control_points` (align anchor landmarks
with a similarity transform, then pick the nearest front-facing vertex).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.model.geometry import vertex_normals

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

FORMAT = "facepuppet-control-points"
ROLES = ("nose_tip", "forehead", "eye_inner_L", "eye_inner_R")

# Multi-PIE (68) landmark → control-point name. Landmarks 0–16 lie on the
# character's right (x < 0) first; names use the character's own sides.
_MULTIPIE = {
    4: "jaw_R", 6: "jaw_chin_R", 8: "chin", 10: "jaw_chin_L", 12: "jaw_L",
    17: "brow_outer_R", 19: "brow_mid_R", 21: "brow_inner_R",
    22: "brow_inner_L", 24: "brow_mid_L", 26: "brow_outer_L",
    27: "nose_root", 30: "nose_tip", 31: "nostril_R", 33: "nose_base", 35: "nostril_L",
    36: "eye_outer_R", 37: "lid_upper_outer_R", 38: "lid_upper_inner_R", 39: "eye_inner_R",
    40: "lid_lower_inner_R", 41: "lid_lower_outer_R",
    42: "eye_inner_L", 43: "lid_upper_inner_L", 44: "lid_upper_outer_L", 45: "eye_outer_L",
    46: "lid_lower_outer_L", 47: "lid_lower_inner_L",
    48: "mouth_corner_R", 50: "lip_upper_R", 51: "lip_upper", 52: "lip_upper_L", 54: "mouth_corner_L",
    56: "lip_lower_L", 57: "lip_lower", 58: "lip_lower_R",
    60: "mouth_inner_R", 62: "lip_upper_inner", 64: "mouth_inner_L", 66: "lip_lower_inner",
}
# Anchors for proposing control points on another mesh (Multi-PIE numbering).
ANCHOR_NAMES = ("eye_R", "eye_L", "nose_tip", "mouth_corner_R", "mouth_corner_L")
# The same anchors in MediaPipe face-mesh numbering (eye = mean of its corners).
MEDIAPIPE_ANCHORS = {"eye_R": (33, 133), "eye_L": (362, 263), "nose_tip": (1,), "mouth_corner_R": (61,),
                     "mouth_corner_L": (291,)}


@dataclass(frozen=True, eq=False)
class ControlPoints:
    """An ordered set of named control-point vertices, validated when built.

    Attributes
    ----------
    names : tuple of n_c str, unique
    vertices : ndarray of shape (n_c,), int64, vertex indices
    """

    names: tuple
    vertices: np.ndarray

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices)
        if v.ndim != 1 or v.dtype.kind not in "iu" or len(v) != len(self.names) or len(v) == 0:
            raise ValueError(f"control points: expected {len(self.names)} integer vertex indices, "
                             f"got {v.dtype} {v.shape}")
        if len(set(self.names)) != len(self.names):
            dup = next(n for n in self.names if self.names.count(n) > 1)
            raise ValueError(f"control points: duplicate name {dup!r}")
        object.__setattr__(self, "vertices", v.astype(np.int64))

    def index(self, name: str) -> int:
        """Row of ``name``, or ValueError naming what is missing."""
        try:
            return self.names.index(name)
        except ValueError:
            raise InputFileError(f"control points: no point named {name!r} (the role needs it)") from None

    def vertex(self, name: str) -> int:
        return int(self.vertices[self.index(name)])

    def check(self, n_vertices: int, where: str = "control points") -> ControlPoints:
        if self.vertices.min() < 0 or self.vertices.max() >= n_vertices:
            raise InputFileError(f"{where}: vertex indices must lie in 0..{n_vertices - 1}, "
                                 f"got {self.vertices.min()}..{self.vertices.max()}")
        return self

    def reorder(self, names: Sequence[str]) -> ControlPoints:
        """The points named ``names``, in that order (ValueError if one is missing)."""
        return ControlPoints(tuple(names), np.array([self.vertex(n) for n in names], np.int64))


def write_control_points(path: str | os.PathLike, points: ControlPoints) -> Path:
    path = Path(path)
    doc = {"format": FORMAT, "version": 1,
           "points": [{"name": n, "vertex": int(v)} for n, v in zip(points.names, points.vertices)]}
    path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return path


def read_control_points(path: str | os.PathLike, n_vertices: int | None = None) -> ControlPoints:
    """Read a control-point (or correspondence) file; ValueError names the file and field."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable JSON control-point file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else doc
        raise InputFileError(f"{path}: format: expected {FORMAT!r}, got {found!r}")
    try:
        names = tuple(str(p["name"]) for p in doc["points"])
        verts = np.array([int(p["vertex"]) for p in doc["points"]], np.int64)
        points = ControlPoints(names, verts)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise InputFileError(f"{path}: points: expected a list of {{name, vertex}} objects ({exc})") from None
    return points.check(n_vertices, str(path)) if n_vertices is not None else points


def front_vertices(vertices: np.ndarray, triangles: np.ndarray, min_normal_z: float = 0.3) -> np.ndarray:
    """Indices of vertices in triangles whose normal faces the viewer (+z) enough, (p,) int64."""
    v = np.asarray(vertices, np.float64)
    used = np.unique(np.asarray(triangles, np.int64))
    normals = vertex_normals(v.astype(np.float32), np.asarray(triangles, np.uint32))
    return used[normals[used, 2] > min_normal_z]


def _front_point(vertices, candidates, x: float, y: float) -> int:
    """The candidate vertex nearest to (x, y) in the image plane."""
    d = np.hypot(vertices[candidates, 0] - x, vertices[candidates, 1] - y)
    return int(candidates[np.argmin(d)])


def ict_control_points(landmarks: ArrayLike, vertices: np.ndarray, triangles: np.ndarray,
                       face_vertices: np.ndarray | None = None) -> ControlPoints:
    """47 control points on a head with 68 Multi-PIE landmarks (40 landmarks + 7 added points).

    The set follows the MPEG-4 feature points, denser at the eyes and mouth:
    6 per eye (corners, two upper and two lower lid points), 3 per brow, the
    outer lip contour (8), the inner lip corners and middles (4: MPEG-4 2.2–2.5),
    nose (5), jaw and chin (5), plus forehead (3), cheekbones and cheeks (4).
    Measured on the ICT head (k = 8, fixed ratio 1.4, median relative RMS error
    over its shapes): 10.4 % with the first set (nose bridge and a mentalis
    point instead of the inner lip corners), 9.8 % with this one; the inner lip
    corners carry the lip-rolling and press shapes.

    Parameters
    ----------
    landmarks : array_like of shape (68,), int, vertex index per Multi-PIE landmark
    vertices : ndarray of shape (n, 3), float, units
    triangles : ndarray of shape (m, 3), int
    face_vertices : ndarray of int or None, where added points may go (default: front-facing vertices)
    """
    lm = np.asarray(landmarks, np.int64)
    if lm.shape != (68,):
        raise InputFileError(f"landmarks: expected 68 Multi-PIE vertex indices, got shape {lm.shape}")
    v = np.asarray(vertices, np.float64)
    cand = front_vertices(v, triangles) if face_vertices is None else np.asarray(face_vertices, np.int64)
    names = list(_MULTIPIE.values())
    verts = [int(lm[i]) for i in _MULTIPIE]
    p = v[lm]
    e = float(np.linalg.norm(p[42] - p[39]))  # inner-eye-corner distance, the face's unit
    added = {"forehead": (0.0, p[27, 1] + 1.4 * e)}
    for side, (brow, eye_out, mouth, jaw) in {"L": (24, 45, 54, 12), "R": (19, 36, 48, 4)}.items():
        added[f"forehead_{side}"] = (p[brow, 0], p[brow, 1] + 0.8 * e)
        added[f"cheekbone_{side}"] = (0.9 * p[eye_out, 0], p[eye_out, 1] - 0.8 * e)
        added[f"cheek_{side}"] = ((p[mouth, 0] + p[jaw, 0]) / 2, (p[mouth, 1] + p[30, 1]) / 2)
    for name, (x, y) in added.items():
        names.append(name)
        verts.append(_front_point(v, cand, x, y))
    return ControlPoints(tuple(names), np.array(verts, np.int64))


def similarity_transform(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity (Umeyama 1991) mapping ``source`` points onto ``target``.

    Returns (scale, rotation (3, 3), translation (3,)) with target ≈ scale * R @ source + t.
    """
    a, b = np.asarray(source, np.float64), np.asarray(target, np.float64)
    ma, mb = a.mean(0), b.mean(0)
    a0, b0 = a - ma, b - mb
    u, s, vt = np.linalg.svd(b0.T @ a0 / len(a))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    scale = float(np.trace(np.diag(s) @ d) / (a0**2).sum(1).mean())
    return scale, r, mb - scale * r @ ma


def anchor_positions(vertices: np.ndarray, groups: dict) -> np.ndarray:
    """(len(ANCHOR_NAMES), 3) anchor positions: each the mean of its vertex group."""
    v = np.asarray(vertices, np.float64)
    return np.stack([v[list(groups[name])].mean(0) for name in ANCHOR_NAMES])


def propose_control_points(
    source_points: np.ndarray,
    source_anchors: np.ndarray,
    target_vertices: np.ndarray,
    target_anchors: np.ndarray,
    candidates: np.ndarray,
    names: Sequence[str],
) -> ControlPoints:
    """Propose target control points: align anchors, then take the nearest free candidate vertex.

    Parameters
    ----------
    source_points : ndarray of shape (n_c, 3), source control-point positions, source units
    source_anchors, target_anchors : ndarray of shape (a, 3), a >= 3 matching landmarks
    target_vertices : ndarray of shape (n, 3), target units
    candidates : ndarray of int, target vertices allowed as control points
    names : sequence of n_c str

    Each point takes the nearest candidate not yet taken, so no two share a vertex.
    """
    s, r, t = similarity_transform(source_anchors, target_anchors)
    moved = s * np.asarray(source_points, np.float64) @ r.T + t
    cand = np.asarray(candidates, np.int64)
    if len(cand) < len(moved):
        raise InputFileError(f"candidates: {len(cand)} target vertices cannot hold {len(moved)} control points")
    tree = cKDTree(np.asarray(target_vertices, np.float64)[cand])
    taken: set = set()
    chosen = []
    for point in moved:
        _, order = tree.query(point, k=min(len(cand), len(moved) + 1))
        pick = next(int(cand[i]) for i in np.atleast_1d(order) if int(cand[i]) not in taken)
        taken.add(pick)
        chosen.append(pick)
    return ControlPoints(tuple(names), np.array(chosen, np.int64))
