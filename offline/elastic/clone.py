"""Expression cloning to a mesh of other topology, Yano & Harada (2009) §5.

The source's expression parameters (control displacements) are carried to
corresponding control points on the target: each displacement is expressed in
the source's face frame (y up, x the character's left, +z forward) and in
FAPU (the inner-eye-corner distance), then taken back to the target's frame
and scale. The target gets its own elastic basis, so the cloned parameters
deform its whole surface.

Symbols → code names:

    ES (FAPU: inner-eye-corner distance)   fapu(...)
    R (world → face-frame rotation, rows x, y, z)   face_frame(...)
    u_s, u_t (source / target control displacement)   params, cloned
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.elastic.thin_plate import thin_plate

WARP_SMOOTHING = 0.5  # the control points' map need not pass exactly through each (inner-eye distances)


def fapu(positions: np.ndarray, points: ControlPoints) -> float:
    """Inner-eye-corner distance ES (units), the FAPU of §5."""
    es = float(np.linalg.norm(positions[points.index("eye_inner_L")] - positions[points.index("eye_inner_R")]))
    if es <= 0:
        raise InputFileError("control points: eye_inner_L and eye_inner_R coincide; FAPU would be zero")
    return es


def face_frame(positions: np.ndarray, points: ControlPoints) -> np.ndarray:
    """World → face-frame rotation (3, 3): rows are x (character's left), y (up), z (forward), §5.

    x runs from the right to the left inner eye corner; y from the nose tip to
    the forehead, made orthogonal to x; z = x × y.
    """
    x = positions[points.index("eye_inner_L")] - positions[points.index("eye_inner_R")]
    x = x / np.linalg.norm(x)
    y = positions[points.index("forehead")] - positions[points.index("nose_tip")]
    y = y - x * (x @ y)
    if np.linalg.norm(y) < 1e-9:
        raise InputFileError("control points: nose_tip → forehead is parallel to the eye line; no face frame")
    y = y / np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


def clone_parameters(params: np.ndarray, source_positions: np.ndarray, source_points: ControlPoints,
                     target_positions: np.ndarray, target_points: ControlPoints) -> np.ndarray:
    """Carry control displacements from source to target (§5).

    Parameters
    ----------
    params : ndarray of shape (..., n_c, 3), float, source units, rows in ``source_points`` order
    source_positions : ndarray of shape (n_c, 3), neutral source control positions
    source_points, target_points : ControlPoints with the same names in the same order
    target_positions : ndarray of shape (n_c, 3), neutral target control positions

    Returns
    -------
    ndarray of the shape of ``params``, float32, target units
    """
    if tuple(source_points.names) != tuple(target_points.names):
        raise InputFileError("correspondences: target control points must carry the source's names in its order")
    src, tgt = np.asarray(source_positions, np.float64), np.asarray(target_positions, np.float64)
    r_s, r_t = face_frame(src, source_points), face_frame(tgt, target_points)
    scale = fapu(tgt, target_points) / fapu(src, source_points)
    local = np.asarray(params, np.float64) @ r_s.T  # into the source face frame (§5 axis alignment)
    return (scale * local @ r_t).astype(np.float32)  # FAPU scale, back out of the target frame (§5)


def clone_parameters_warped(params: np.ndarray, source_positions: np.ndarray, source_points: ControlPoints,
                            target_positions: np.ndarray, target_points: ControlPoints,
                            smoothing: float = WARP_SMOOTHING) -> np.ndarray:
    """Carry control displacements from source to target through the map between their control points.

    §5 scales every displacement by one ratio (FAPU); a face whose eyes are smaller relative to its inner-eye
    distance than the source's, or whose lip line lies lower, needs each point's displacement scaled and
    turned by its own neighbourhood. Here the source's control points (in its face frame, FAPU-scaled) are
    mapped onto the target's (in its face frame) by a thin-plate spline W (:func:`~.thin_plate.thin_plate`,
    ``smoothing`` in inner-eye distances), and a displacement u of point p becomes W(p + u) − W(p): what
    the same motion is on a face made by bending space from the source's to the target's (a point moved
    onto another point's rest place lands on that point's place on the target). On the source itself W is
    the identity and this is §5. Same arguments and result as :func:`clone_parameters`.
    """
    if tuple(source_points.names) != tuple(target_points.names):
        raise InputFileError("correspondences: target control points must carry the source's names in its order")
    src, tgt = np.asarray(source_positions, np.float64), np.asarray(target_positions, np.float64)
    r_s, r_t = face_frame(src, source_points), face_frame(tgt, target_points)
    es_t = fapu(tgt, target_points)
    scale = es_t / fapu(src, source_points)
    s_local = scale * src @ r_s.T  # source points in its face frame, at the target's size
    warp = thin_plate(s_local, tgt @ r_t.T, smoothing * es_t)
    u = scale * np.asarray(params, np.float64) @ r_s.T
    flat = u.reshape(-1, u.shape[-2], 3)
    moved = np.stack([warp(s_local + f) for f in flat]) - warp(s_local)[None]
    return (moved.reshape(u.shape) @ r_t).astype(np.float32)  # back out of the target frame


def mesh_character(vertices: np.ndarray, triangles: np.ndarray, name: str, units: str = "cm") -> Character:
    """A shape-less skin-coloured character for a bare target mesh."""
    v = np.asarray(vertices, np.float32)
    t = np.asarray(triangles, np.uint32)
    return character_with_shapes(
        Character(
            name=name, units=units, vertices=v, triangles=t, triangle_material=np.zeros(len(t), np.uint16),
            vertex_color=np.tile(np.array([0.62, 0.36, 0.25], np.float32), (len(v), 1)),
            material_names=("skin",), material_params=np.array([[0.25, 18.0, MATERIAL_KINDS["skin"], 0]], np.float32),
            pivot=v.mean(0).astype(np.float32), shape_names=(), delta_offsets=np.zeros(1, np.int64),
            delta_indices=np.zeros(0, np.uint32), delta_positions=np.zeros((0, 3), np.float32),
            delta_normals=np.zeros((0, 3), np.float32),
        ),
        {},
    )


def character_with_shapes(base: Character, shapes: dict) -> Character:
    """``base``'s mesh and materials with the given dense shapes (name → (n, 3) displacements)."""
    names = tuple(shapes)
    if names:
        dense = np.stack([np.asarray(shapes[n], np.float32) for n in names])
        n0 = vertex_normals(base.vertices, base.triangles)
        dense_n = np.stack([vertex_normals(base.vertices + d, base.triangles) - n0 for d in dense])
        offsets, indices, both = sparse_deltas(np.concatenate([dense, dense_n], axis=2), tolerance=1e-6)
    else:
        offsets, indices, both = np.zeros(1, np.int64), np.zeros(0, np.uint32), np.zeros((0, 6), np.float32)
    return Character(
        name=base.name, units=base.units, vertices=base.vertices, triangles=base.triangles,
        triangle_material=base.triangle_material, vertex_color=base.vertex_color,
        material_names=base.material_names, material_params=base.material_params, pivot=base.pivot,
        shape_names=names, delta_offsets=offsets, delta_indices=indices,
        delta_positions=np.ascontiguousarray(both[:, :3]), delta_normals=np.ascontiguousarray(both[:, 3:]),
    )


def clone_model(
    source: ElasticModel,
    target_points: ControlPoints,
    target_vertices: np.ndarray,
    build_model: Callable[[ControlPoints, np.ndarray, Sequence[str]], ElasticModel],
    warped: bool = False,
) -> ElasticModel:
    """An elastic model for the target: its own basis, the source's parameters cloned (§5).

    ``build_model(points, params, shape_names)`` fits the target basis and
    returns the ElasticModel (the caller's settings: k, fixed ratio).
    ``warped``: carry the parameters by :func:`clone_parameters_warped`
    rather than §5's one scale.
    """
    names = tuple(source.control_names)
    src_points = ControlPoints(names, source.arrays["control_vertices"])
    tgt_points = target_points.reorder(names)
    tv = np.asarray(target_vertices, np.float64)
    carry = clone_parameters_warped if warped else clone_parameters
    cloned = carry(
        source.arrays["params"], source.arrays["control_positions"], src_points, tv[tgt_points.vertices], tgt_points
    )
    return build_model(tgt_points, cloned, source.shape_names)
