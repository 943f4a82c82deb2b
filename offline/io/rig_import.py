"""Blendshape rig (neutral OBJ + one OBJ per shape) -> :class:`Character` table.

Every shape file must list the neutral's vertices in the same order (the
topology is shared, so only its ``v`` lines are read). A shape's delta is
``shape - neutral`` per vertex; its normal delta is ``normal(shape) -
normal(neutral)`` with area-weighted vertex normals. Per shape, a vertex is
stored when its position moves more than ``tolerance`` or its normal turns
by more than ``NORMAL_TOLERANCE`` (normals change at the border of a moved
region). Fitting is float64; the table is float32.

Materials get a shading *kind* from their name (see :data:`KIND_WORDS`) and
every vertex an albedo from its kind: eyes are coloured sclera / iris / pupil
by the angle of the vertex around its eyeball's centre from +z (so an eye
modelled as a full sphere, as ICT's sclera is, still shows an iris), and skin
inside the outer lip contour of 68 Multi-PIE landmarks (``vertex_indices.json``,
ICT format) gets a lip tint with a soft edge.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.files.tables import hash_inputs, naming_file
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.model.geometry import incidence_matrix

from facepuppet.offline.io.mesh_format import refuse_non_obj
from facepuppet.offline.io.mtl import MtlMaterial, read_mtl
from facepuppet.offline.io.obj import ObjError, ObjMesh, read_obj, read_vertices_only

__all__ = ["import_rig", "material_kind", "NORMAL_TOLERANCE", "KIND_WORDS"]

NORMAL_TOLERANCE = 1e-4
UNITS_PER_CM = {"cm": 1.0, "mm": 10.0, "m": 0.01}
#: degrees about +Y that turn a mesh facing each axis to the stored convention (facing +Z, Y up)
FORWARD_TURNS = {"+z": 0.0, "-z": 180.0, "+x": -90.0, "-x": 90.0}

# First match wins, in this order; a name matching none is skin. "cornea" is
# hidden, not eye: it is a transparent shell and, drawn opaque, would cover the iris. The eye's thin
# layers (ICT: eye occlusion, lacrimal fluid, eye blend) are drawn blended (renderer: vertex_opacity).
KIND_WORDS = (
    ("hidden", ("cornea",)),
    ("occlusion", ("occlusion",)),
    ("film", ("blend", "lacrimal", "tear")),
    ("eye", ("sclera", "iris", "pupil", "eyeball")),
    ("teeth", ("teeth", "tooth")),
    ("mouth", ("gum", "tongue", "mouth")),
    ("lashes", ("lash",)),
    ("lips", ("lip",)),
)
# Albedo per kind, linear RGB; eyes split into sclera / iris / pupil.
KIND_COLOR = {
    "skin": (0.80, 0.58, 0.48),
    "lips": (0.72, 0.36, 0.36),
    "teeth": (0.92, 0.90, 0.82),
    "mouth": (0.55, 0.18, 0.20),
    "lashes": (0.05, 0.04, 0.04),
    "hidden": (0.5, 0.5, 0.5),
    "occlusion": (0.03, 0.02, 0.02),
    "film": (0.80, 0.60, 0.56),
}
SCLERA, IRIS, PUPIL = (0.92, 0.90, 0.86), (0.25, 0.15, 0.08), (0.02, 0.02, 0.02)
IRIS_DEG, PUPIL_DEG = 25.0, 10.0
# [specular, shininess] when there is no MTL entry
KIND_SHINE = {"skin": (0.05, 18), "lips": (0.15, 24), "eye": (0.6, 60), "teeth": (0.4, 40),
              "mouth": (0.3, 30), "lashes": (0.0, 1), "hidden": (0.0, 1),
              "occlusion": (0.0, 1), "film": (0.6, 60)}  # fmt: skip
LIP_OUTER = slice(48, 60)  # Multi-PIE 68: outer lip contour; 48 and 54 are the mouth corners
LIP_DEPTH_CM, LIP_EDGE_CM = 1.0, 0.3

Progress = Callable[[int, int, str], None]


def material_kind(name: str) -> str:
    """Shading kind of a material from its name (lower-cased substring match, :data:`KIND_WORDS`)."""
    low = name.lower()
    for kind, words in KIND_WORDS:
        if any(w in low for w in words):
            return kind
    return "skin"


def import_rig(
    neutral_path: str | os.PathLike,
    shapes_dir: str | os.PathLike | None,
    *,
    shapes: Sequence[str | os.PathLike] | None = None,
    tolerance: float = 1e-5,
    name: str | None = None,
    units: str = "cm",
    landmarks: str | os.PathLike | None = None,
    pivot: Sequence[float] | None = None,
    forward: str = "+z",
    progress: Progress | None = None,
) -> Character:
    """Import a blendshape rig as a character.

    Parameters
    ----------
    neutral_path : path of the neutral OBJ (quads/polygons are fan-triangulated)
    shapes_dir : folder of shape OBJs; every ``*.obj`` in it except the neutral, sorted by name;
        None: a character without shapes (a static mesh; the glTF import writes these too)
    shapes : optional explicit shape files (relative to ``shapes_dir``; ".obj" may be left out)
    tolerance : float, units; a vertex moving no more than this (and whose normal turns less
        than ``NORMAL_TOLERANCE``) is not stored for that shape
    name : character name; default the neutral's folder name
    units : "cm", "mm" or "m", the units of the files (ICT is cm)
    landmarks : ICT ``vertex_indices.json``; default the one beside the neutral, if any
    pivot : (3,) float, units; default (centre x, min y + 0.35 height, centre z - 0.1 depth)
        of the bounding box, a point near the top of the neck for a head with neck
    forward : the axis the face looks along in the files ("+z", "-z", "+x" or "-x", Y up); the character is
        turned about +Y to the stored convention (facing +Z), its shapes with it
    progress : callable(i, n, shape_name) called after each shape is read, i from 1

    Returns
    -------
    Character
        shape names are the file stems as spelled (e.g. ``eyeBlink_L``); ``metadata`` holds
        settings, ``input_hash`` and metrics (per shape: moved, stored, max_displacement).

    Raises
    ------
    FileNotFoundError
        the neutral, the folder, a shape or the landmark file is missing.
    ValueError
        no shapes, a shape whose vertex count differs from the neutral's (names both files and
        counts), bad numbers (:class:`~facepuppet.offline.io.obj.ObjError`, names file and line).
    """
    neutral_path = Path(neutral_path)
    shapes_dir = Path(shapes_dir) if shapes_dir is not None else None
    if units not in UNITS_PER_CM:
        raise ValueError(f"units: expected one of {sorted(UNITS_PER_CM)}, got {units!r}")
    if not (tolerance >= 0 and np.isfinite(tolerance)):
        raise UsageError(f"tolerance: expected a finite number >= 0, got {tolerance!r}")
    if forward not in FORWARD_TURNS:
        raise ValueError(f"forward: expected one of {', '.join(FORWARD_TURNS)}, got {forward!r}")
    regular_file(neutral_path, "neutral OBJ")  # missing: not found; a FIFO or device: refused, never opened
    refuse_non_obj(neutral_path, "the neutral")
    if shapes_dir is None and shapes:
        raise ValueError("shapes: an explicit list of shapes needs a shapes folder")
    shape_paths = [] if shapes_dir is None else _shape_paths(neutral_path, shapes_dir, shapes)
    for shape in shape_paths:
        refuse_non_obj(shape, "a shape")

    mesh = read_obj(neutral_path)
    if len(mesh.triangles) == 0:
        raise ObjError(neutral_path, None, "no faces ('f' lines): a character needs a surface")
    deltas, per_shape = _sparse_deltas(mesh, neutral_path, shape_paths, tolerance, progress)
    if forward != "+z":
        mesh, deltas = _turned(mesh, deltas, FORWARD_TURNS[forward])

    mtl_path, mtl = _read_materials(neutral_path, mesh)
    kinds = [material_kind(m) for m in mesh.material_names]
    landmark_path, marks = _find_landmarks(neutral_path, landmarks, len(mesh.vertices))
    vertex_kind, vertex_material = _vertex_kinds(mesh, kinds)
    color = _vertex_colors(mesh.vertices, vertex_kind, vertex_material, mesh.material_names, marks, units)
    pivot, pivot_rule = _pivot(mesh.vertices, pivot)

    inputs = [neutral_path, *shape_paths] + [p for p in (mtl_path, landmark_path) if p and p.is_file()]
    settings = {
        "neutral": str(neutral_path),
        "shapes_dir": str(shapes_dir) if shapes_dir is not None else None,
        "shape_files": [p.name for p in shape_paths],
        "tolerance": float(tolerance),
        "normal_tolerance": NORMAL_TOLERANCE,
        "mtl": str(mtl_path) if mtl else None,
        "landmarks": str(landmark_path) if marks is not None else None,
        "pivot_rule": pivot_rule,
        **({"forward": forward} if forward != "+z" else {}),
    }
    with naming_file(neutral_path):  # the character's own refusals name the neutral OBJ, not "<tables>"
        return _character(name or neutral_path.parent.name or neutral_path.stem, units, mesh, color, kinds, mtl,
                          pivot, shape_paths, deltas, settings, per_shape, inputs)


def turn_about_y(degrees: float) -> np.ndarray:
    """(3, 3) float64 rotation by ``degrees`` about +Y (row vectors turn as ``v @ r.T``)."""
    a = np.radians(degrees)
    return np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])


def _turned(mesh: ObjMesh, deltas: dict, degrees: float) -> tuple[ObjMesh, dict]:
    """The mesh and its shapes' position and normal deltas turned by ``degrees`` about +Y."""
    r = turn_about_y(degrees)
    turned = dict(deltas)
    for key in ("delta_positions", "delta_normals"):
        turned[key] = (deltas[key].astype(np.float64) @ r.T).astype(deltas[key].dtype)
    return dataclasses.replace(mesh, vertices=mesh.vertices @ r.T, normals=mesh.normals @ r.T), turned


def _character(name, units, mesh, color, kinds, mtl, pivot, shape_paths, deltas, settings, per_shape,
               inputs) -> Character:
    return Character(
        name=name,
        units=units,
        vertices=mesh.vertices.astype(np.float32),
        triangles=mesh.triangles.astype(np.uint32),
        triangle_material=mesh.triangle_material.astype(np.uint16),
        vertex_color=color.astype(np.float32),
        material_names=tuple(mesh.material_names),
        material_params=_material_params(mesh.material_names, kinds, mtl),
        pivot=pivot.astype(np.float32),
        shape_names=tuple(p.stem for p in shape_paths),
        **deltas,
        metadata={
            "settings": settings,
            "metrics": _metrics(mesh, len(shape_paths), deltas, color, per_shape),
            "input_hash": hash_inputs(*inputs, json.dumps(settings, sort_keys=True).encode()),
        },
    )


def _shape_paths(neutral: Path, folder: Path, shapes) -> list[Path]:
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: shapes folder not found")
    if shapes is None:
        paths = sorted(
            (p for p in folder.glob("*.obj") if p.is_file() and p.resolve() != neutral.resolve()),
            key=lambda p: p.name,
        )
        if not paths:
            raise InputFileError(f"{folder}: no shape OBJ files (other than the neutral) in the folder")
        return paths
    paths = []
    for s in shapes:
        p = Path(s) if Path(s).is_absolute() else folder / s
        p = p if p.suffix.lower() == ".obj" else p.with_name(p.name + ".obj")
        if not p.is_file():
            raise FileNotFoundError(f"{p}: shape OBJ not found")
        paths.append(p)
    if not paths:
        raise ValueError("shapes: the explicit list of shapes is empty")
    stems = [p.stem for p in paths]
    if len(set(stems)) != len(stems):
        raise ValueError(f"shapes: names must be unique, got {stems}")
    return paths


def _sparse_deltas(
    mesh: ObjMesh, neutral_path: Path, shape_paths: list[Path], tolerance: float, progress: Progress | None
) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Read every shape and keep its stored vertices; returns the :class:`Character`'s ``delta_*`` arrays
    (positions and normals float32, indices uint32, offsets int64) and the metrics per shape name."""
    neutral = mesh.vertices
    normals_of = _NormalOperator(len(neutral), mesh.triangles)
    neutral_normals = normals_of(neutral)
    offsets, indices, d_pos, d_nrm, per_shape = [0], [], [], [], {}
    for i, path in enumerate(shape_paths, start=1):
        shape = _read_shape(path, neutral_path, len(neutral))
        delta = shape - neutral
        too_far = np.abs(delta) > np.finfo(np.float32).max
        if too_far.any():  # each file is within float32, their difference is not: a character stores float32
            vertex = int(np.argmax(too_far.any(axis=1)))
            raise ObjError(path, None, f"moves vertex {vertex} by {delta[vertex].tolist()}, beyond the float32 range "
                                       f"a character stores")
        d_normal = normals_of(shape) - neutral_normals
        keep, per_shape[path.stem] = _stored_vertices(delta, d_normal, tolerance)
        indices.append(keep.astype(np.uint32))
        d_pos.append(delta[keep].astype(np.float32))
        d_nrm.append(d_normal[keep].astype(np.float32))
        offsets.append(offsets[-1] + len(keep))
        if progress is not None:
            progress(i, len(shape_paths), path.stem)
    deltas = {
        "delta_offsets": np.asarray(offsets, dtype=np.int64),
        "delta_indices": np.concatenate(indices) if indices else np.zeros(0, np.uint32),
        "delta_positions": np.concatenate(d_pos) if d_pos else np.zeros((0, 3), np.float32),
        "delta_normals": np.concatenate(d_nrm) if d_nrm else np.zeros((0, 3), np.float32),
    }
    return deltas, per_shape


def _read_shape(path: Path, neutral_path: Path, n_vertices: int) -> np.ndarray:
    """(n_vertices, 3) float64 positions of a shape OBJ, or ValueError naming both files and counts."""
    shape = read_vertices_only(path)
    if len(shape) != n_vertices:
        raise InputFileError(
            f"{path}: has {len(shape)} vertices but the neutral {neutral_path} has {n_vertices}; "
            "a shape must list the neutral's vertices in the same order"
        )
    return shape


def _stored_vertices(delta: np.ndarray, d_normal: np.ndarray, tolerance: float) -> tuple[np.ndarray, dict]:
    """Vertices a shape stores, (k,) int64, and its metrics (moved, stored, max_displacement).

    Stored: moved by more than ``tolerance`` or normal turned by more than ``NORMAL_TOLERANCE``.
    """
    length = np.linalg.norm(delta, axis=1)
    moved = length > tolerance
    keep = np.flatnonzero(moved | (np.linalg.norm(d_normal, axis=1) > NORMAL_TOLERANCE))
    return keep, {"moved": int(moved.sum()), "stored": int(len(keep)), "max_displacement": float(length.max())}


class _NormalOperator:
    """Area-weighted unit vertex normals for a fixed topology (sparse sum of face normals).

    Same result as :func:`facepuppet.runtime.model.geometry.vertex_normals`, in float64,
    with the vertex-face incidence matrix built once for all shapes.
    """

    def __init__(self, n_vertices: int, triangles: np.ndarray):
        self.triangles = triangles
        self.incidence = incidence_matrix(n_vertices, triangles).astype(np.float64)

    def __call__(self, vertices: np.ndarray) -> np.ndarray:
        t = self.triangles
        face = np.cross(vertices[t[:, 1]] - vertices[t[:, 0]], vertices[t[:, 2]] - vertices[t[:, 0]])
        n = self.incidence @ face
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def _read_materials(neutral_path: Path, mesh: ObjMesh) -> tuple[Path | None, dict[str, MtlMaterial]]:
    """The MTL file the neutral names (None when it names none) and its materials ({} when it is missing)."""
    mtl_path = neutral_path.parent / mesh.mtllib if mesh.mtllib else None
    mtl = read_mtl(mtl_path) if mtl_path is not None and mtl_path.is_file() else {}
    return mtl_path, mtl


def _material_params(material_names: list[str], kinds: list[str], mtl: dict[str, MtlMaterial]) -> np.ndarray:
    """(n_materials, 4) float32 [specular, shininess, kind, 0]: the MTL's where it has the material, else KIND_SHINE."""
    return np.array(
        [
            [
                float(np.mean(mtl[m].specular)) if m in mtl else KIND_SHINE[k][0],
                float(mtl[m].shininess) if m in mtl else KIND_SHINE[k][1],
                MATERIAL_KINDS[k],
                0.0,
            ]
            for m, k in zip(material_names, kinds)
        ],
        dtype=np.float32,
    )


def _find_landmarks(
    neutral_path: Path, landmarks: str | os.PathLike | None, n_vertices: int
) -> tuple[Path, np.ndarray | None]:
    """The landmark file (given, else ``vertex_indices.json`` beside the neutral) and its indices.

    The indices are None when the default file is absent; a given file that is absent is an error.
    """
    path = Path(landmarks) if landmarks is not None else neutral_path.parent / "vertex_indices.json"
    if landmarks is not None and not path.is_file():
        raise FileNotFoundError(f"{path}: landmark file not found")
    return path, read_ict_landmarks(path, n_vertices) if path.is_file() else None


def read_ict_landmarks(path: str | os.PathLike, n_vertices: int) -> np.ndarray:
    """(68,) int64 vertex indices of the Multi-PIE landmarks from an ICT ``vertex_indices.json``; an
    InputFileError naming the file and field when it is not one for ``n_vertices`` vertices."""
    path = Path(path)
    try:
        marks = json.loads(path.read_text(encoding="utf-8"))["idx_to_landmark_verts"]
        marks = np.asarray(marks, dtype=np.int64)
    except (ValueError, KeyError, TypeError, OverflowError) as exc:  # ValueError: JSON, UTF-8, not ints
        raise InputFileError(f"{path}: idx_to_landmark_verts: expected a list of 68 vertex indices ({exc})") from None
    if marks.shape != (68,) or marks.min() < 0 or marks.max() >= n_vertices:
        found = f"range {marks.min()}..{marks.max()}" if marks.size else "no index"
        raise InputFileError(
            f"{path}: idx_to_landmark_verts: expected 68 indices in 0..{n_vertices - 1}, "
            f"got shape {marks.shape}, {found}"
        )
    return marks


def _pivot(vertices: np.ndarray, pivot: Sequence[float] | None) -> tuple[np.ndarray, str]:
    """The pivot, (3,) float64, and the rule that gave it: as given, else from the bounding box."""
    if pivot is None:
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        size, centre = hi - lo, (hi + lo) / 2
        pivot = (centre[0], lo[1] + 0.35 * size[1], centre[2] - 0.1 * size[2])
        rule = "bbox: centre x, min y + 0.35 height, centre z - 0.1 depth"
    else:
        rule = "given"
    pivot = np.asarray(pivot, dtype=np.float64)
    if pivot.shape != (3,) or not np.isfinite(pivot).all():
        raise ValueError(f"pivot: expected 3 finite numbers, got {pivot!r}")
    return pivot, rule


def _metrics(mesh: ObjMesh, n_shapes: int, deltas: dict[str, np.ndarray], color: np.ndarray,
             per_shape: dict[str, dict]) -> dict:
    """Sizes of the import for ``metadata["metrics"]``: mesh, stored against dense deltas, lip tint, per shape."""
    n_v = len(mesh.vertices)
    return {
        "n_vertices": n_v,
        "n_triangles": int(len(mesh.triangles)),
        "n_faces": int(mesh.n_faces),
        "stored_deltas": int(deltas["delta_offsets"][-1]),
        "dense_deltas": int(n_shapes * n_v),
        "lip_tinted_vertices": int(np.sum(np.all(np.isclose(color, KIND_COLOR["lips"], atol=0.02), axis=1))),
        "shapes": per_shape,
    }


def _vertex_kinds(mesh, kinds: list[str]) -> tuple[list[str], np.ndarray]:
    """Kind and material per vertex (the first triangle using a vertex decides); unused -> skin."""
    material = np.full(len(mesh.vertices), -1, dtype=np.int64)
    corners = mesh.triangles.reshape(-1)
    tri_of_corner = np.repeat(mesh.triangle_material, 3)
    first = np.unique(corners, return_index=True)
    material[first[0]] = tri_of_corner[first[1]]
    kind = np.array(kinds + ["skin"], dtype=object)[material]  # -1 -> the trailing "skin"
    return list(kind), material


def _vertex_colors(vertices, vertex_kind, vertex_material, material_names, marks, units) -> np.ndarray:
    kind = np.asarray(vertex_kind, dtype=object)
    color = np.zeros((len(vertices), 3))
    for k, rgb in KIND_COLOR.items():
        color[kind == k] = rgb
    eye = kind == "eye"
    if eye.any():
        names = np.array([n.lower() for n in material_names] + [""], dtype=object)[vertex_material]
        color[eye] = _eye_colors(vertices, eye, names)
    if marks is not None:
        w = _lip_weight(vertices, kind == "skin", marks, UNITS_PER_CM[units])
        color += w[:, None] * (np.asarray(KIND_COLOR["lips"]) - color)
    return color


def _eye_colors(vertices: np.ndarray, eye: np.ndarray, names: np.ndarray) -> np.ndarray:
    """Albedo of the eye vertices: pupil within PUPIL_DEG of +z around the eyeball centre, iris within IRIS_DEG."""
    idx = np.flatnonzero(eye)
    out = np.empty((len(idx), 3))
    mid_x = (vertices[:, 0].min() + vertices[:, 0].max()) / 2
    for side in (vertices[idx, 0] >= mid_x, vertices[idx, 0] < mid_x):
        if not side.any():
            continue
        p = vertices[idx[side]]
        angle = np.degrees(np.arccos(np.clip(_unit(p - _sphere_centre(p))[:, 2], -1, 1)))
        is_iris = np.array(["iris" in n for n in names[idx[side]]])
        is_pupil = np.array(["pupil" in n for n in names[idx[side]]])
        rgb = np.where(is_iris[:, None], IRIS, SCLERA)
        rgb[angle < IRIS_DEG] = IRIS
        rgb[(angle < PUPIL_DEG) | is_pupil] = PUPIL
        out[side] = rgb
    return out


def _sphere_centre(points: np.ndarray) -> np.ndarray:
    """Least-squares sphere centre (|p|^2 = 2 p.c + k, linear in c and k); the centroid if degenerate."""
    a = np.c_[2 * points, np.ones(len(points))]
    solution, _, rank, _ = np.linalg.lstsq(a, (points**2).sum(axis=1), rcond=None)
    return solution[:3] if rank == 4 else points.mean(axis=0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _lip_weight(vertices: np.ndarray, skin: np.ndarray, marks: np.ndarray, per_cm: float) -> np.ndarray:
    """Lip tint 0..1 per vertex: skin inside the outer lip contour (x-y), in front of the mouth corners.

    Soft edge: weight = smoothstep over a band LIP_EDGE_CM wide centred on the contour.
    """
    contour = vertices[marks[LIP_OUTER], :2]
    corners_z = vertices[marks[[48, 54]], 2].mean()
    cand = np.flatnonzero(skin & (vertices[:, 2] > corners_z - LIP_DEPTH_CM * per_cm))
    q = vertices[cand, :2]
    a, b = contour, np.roll(contour, -1, axis=0)
    inside = np.zeros(len(q), dtype=bool)
    dist = np.full(len(q), np.inf)
    for (ax, ay), (bx, by) in zip(a, b):
        crosses = (ay > q[:, 1]) != (by > q[:, 1])  # even-odd ray test along +x
        x_at = ax + (q[:, 1] - ay) * (bx - ax) / np.where(by == ay, 1.0, by - ay)
        inside ^= crosses & (q[:, 0] < x_at)
        edge = np.array([bx - ax, by - ay])
        t = np.clip(((q - (ax, ay)) @ edge) / max(edge @ edge, 1e-30), 0, 1)
        dist = np.minimum(dist, np.linalg.norm(q - (np.array([ax, ay]) + t[:, None] * edge), axis=1))
    signed = np.where(inside, dist, -dist) / (LIP_EDGE_CM * per_cm) + 0.5
    s = np.clip(signed, 0, 1)
    weight = np.zeros(len(vertices))
    weight[cand] = s * s * (3 - 2 * s)
    return weight
