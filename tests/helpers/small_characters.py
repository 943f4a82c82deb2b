"""Small characters built in code for renderer, deformation and contact-sheet tests."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.character_parts import Expressions, Layout, Look, Skeleton, identity_look
from facepuppet.runtime.model.geometry import vertex_normals


def uv_sphere(n_lat: int = 24, n_lon: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere: vertices (n, 3) float32, counter-clockwise outward triangles (m, 3) uint32."""
    lat = np.linspace(0, np.pi, n_lat + 1)
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.sin(la) * np.sin(lo), np.cos(la), np.sin(la) * np.cos(lo)], axis=-1).reshape(-1, 3)
    tris = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = a + n_lon, b + n_lon
            tris += [(a, c, d), (a, d, b)]
    tris = np.array(tris, dtype=np.uint32)
    # drop degenerate pole triangles (repeated pole vertices)
    area = np.linalg.norm(np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]]), axis=1)
    return v.astype(np.float32), tris[area > 1e-9]


def sphere_character(with_hidden: bool = True) -> Character:
    """A unit-sphere "head" with shapes jawOpen (lower half drops) and puff (widens), an "eye" cap
    and, optionally, a hidden quad in front of the face that must never be drawn."""
    v, tris = uv_sphere()
    mats = np.zeros(len(tris), dtype=np.uint16)
    centroid = v[tris].mean(axis=1)
    mats[(centroid[:, 2] > 0.8) & (centroid[:, 1] > 0.25) & (np.abs(centroid[:, 0]) > 0.1)] = 1  # eyes
    color = np.tile(np.array([0.6, 0.4, 0.3], np.float32), (len(v), 1))
    names = ["skin", "eye"]
    params = [[0.15, 20, MATERIAL_KINDS["skin"], 0], [0.9, 80, MATERIAL_KINDS["eye"], 0]]
    if with_hidden:
        base = len(v)
        quad = np.array([[-0.8, -0.8, 1.5], [0.8, -0.8, 1.5], [0.8, 0.8, 1.5], [-0.8, 0.8, 1.5]], np.float32)
        v = np.vstack([v, quad])
        color = np.vstack([color, np.ones((4, 3), np.float32)])
        tris = np.vstack([tris, np.array([[0, 1, 2], [0, 2, 3]], np.uint32) + base])
        mats = np.concatenate([mats, np.full(2, 2, np.uint16)])
        names.append("occluder")
        params.append([0, 1, MATERIAL_KINDS["hidden"], 0])
    jaw = np.zeros_like(v)
    lower = v[:, 1] < -0.1
    jaw[lower, 1] = -0.4 * (-v[lower, 1])
    jaw[len(v) - 4 * with_hidden:] = 0
    puff = np.zeros_like(v)
    puff[: len(v) - 4 * with_hidden, 0] = 0.25 * v[: len(v) - 4 * with_hidden, 0]
    return make_character(v, tris, mats, color, names, params, {"jawOpen": jaw, "puff": puff})


def make_character(v, tris, mats, color, material_names, params, shapes: dict) -> Character:
    """A Character whose normal deltas are those of the shapes at weight 1."""
    dense = np.stack(list(shapes.values())).astype(np.float32)
    n0 = vertex_normals(v, tris)
    dense_n = np.stack([vertex_normals(v + d, tris) - n0 for d in dense])
    # A vertex that stays put can still turn (its neighbours moved): keep both in one index set.
    offsets, indices, both = sparse_deltas(np.concatenate([dense, dense_n], axis=2), tolerance=1e-7)
    positions, normals = np.ascontiguousarray(both[:, :3]), np.ascontiguousarray(both[:, 3:])
    return Character(
        name="sphere",
        units="cm",
        vertices=np.asarray(v, np.float32),
        triangles=np.asarray(tris, np.uint32),
        triangle_material=np.asarray(mats, np.uint16),
        vertex_color=np.asarray(color, np.float32),
        material_names=tuple(material_names),
        material_params=np.asarray(params, np.float32),
        pivot=np.zeros(3, np.float32),
        shape_names=tuple(shapes),
        delta_offsets=offsets,
        delta_indices=indices,
        delta_positions=positions,
        delta_normals=normals,
    )


def grid_face(extra: bool = False) -> Character:
    """A gently curved 21 x 21 sheet facing +z, cm, with shapes jawOpen (lower half drops) and puff (+z).

    ``extra`` adds jawClose (the opposite of jawOpen), eyeLookIn_L (a copy of puff, a gaze name) and
    cornerBump (moves only the sheet's top-left corner, far from every marker).
    """
    x, y = np.meshgrid(np.linspace(-5, 5, 21), np.linspace(-7, 7, 21))
    v = np.c_[x.ravel(), y.ravel(), 3.0 - 0.04 * (x.ravel() ** 2 + y.ravel() ** 2)].astype(np.float32)
    idx = np.arange(441).reshape(21, 21)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.r_[np.c_[a, b, d], np.c_[a, d, c]].astype(np.uint32)
    if vertex_normals(v, tris)[220, 2] < 0:
        tris = tris[:, ::-1].copy()
    jaw = np.zeros_like(v)
    jaw[:, 1] = np.where(v[:, 1] < 0, 0.1 * v[:, 1], 0.0)
    puff = np.zeros_like(v)
    puff[:, 2] = 0.5 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 8)
    shapes = [jaw, puff]
    names = ("jawOpen", "puff")
    if extra:
        bump = np.zeros_like(v)
        bump[:, 2] = 0.8 * np.exp(-((v[:, 0] + 5) ** 2 + (v[:, 1] - 7) ** 2) / 0.5)
        shapes += [-jaw, puff.copy(), bump]
        names += ("jawClose", "eyeLookIn_L", "cornerBump")
    dense = np.stack(shapes)
    offsets, indices, both = sparse_deltas(np.concatenate([dense, np.zeros_like(dense)], axis=2), tolerance=1e-7)
    return Character(name="grid", units="cm", vertices=v, triangles=tris,
                     triangle_material=np.zeros(len(tris), np.uint16), vertex_color=np.full((441, 3), 0.5, np.float32),
                     material_names=("skin",),
                     material_params=np.array([[0.1, 10, MATERIAL_KINDS["skin"], 0]], np.float32),
                     pivot=np.zeros(3, np.float32), shape_names=names, delta_offsets=offsets,
                     delta_indices=indices, delta_positions=np.ascontiguousarray(both[:, :3]),
                     delta_normals=np.ascontiguousarray(both[:, 3:]))


def parts_character(**overrides) -> Character:
    """Two triangles, a root and a head node (the top two vertices follow the head), one texture."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    rest = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    rest[1, :3, 3] = (0.5, 1.0, 0.0)
    fields = dict(
        name="parts", units="m", vertices=v, triangles=np.array([[0, 1, 2], [1, 3, 2]], np.uint32),
        triangle_material=np.zeros(2, np.uint16), vertex_color=np.ones((4, 3), np.float32),
        material_names=("mat",), material_params=np.zeros((1, 4), np.float32), pivot=np.zeros(3, np.float32),
        shape_names=("s",), delta_offsets=np.array([0, 1]), delta_indices=np.array([2], np.uint32),
        delta_positions=np.ones((1, 3), np.float32), delta_normals=np.zeros((1, 3), np.float32),
        metadata={"settings": {"source": {"format": "vrm0", "credits": "Quad by Someone, CC BY 4.0"}}},
        skeleton=Skeleton(("root", "head"), np.array([-1, 0], np.int32), rest,
                          np.array([[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]], np.uint16),
                          np.tile(np.array([1, 0, 0, 0], np.float32), (4, 1)), {"head": 1}),
        look=Look(texture_names=("t0",), texture_info=np.array([[0, 2, 2, 0, 0, 0, 0]], np.int32),
                  texture_pixels=np.arange(16, dtype=np.uint8).reshape(4, 4), **identity_look(4, 1)),
        expressions=Expressions(("Blink",), ("Blink",), np.array([0, 1], np.int64), np.array([0], np.uint32),
                                np.array([0.5], np.float32), np.zeros((1, 4), np.int32)),
        layout=Layout(("m",), np.array([[0, 4, 0, 2, 0, 0]], np.int64)),
    )
    fields.update(overrides)
    return Character(**fields)
