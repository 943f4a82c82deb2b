"""Small characters with glTF / VRM parts (look, skeleton), built in code for the renderer tests."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import (
    ALPHA_MODES,
    IDENTITY_UV_TRANSFORM,
    SHADING,
    Layout,
    Look,
    Skeleton,
)


def material(base=(1, 1, 1, 1), alpha="OPAQUE", cutoff=0.5, shading="unlit", double_sided=False,
             texture=-1, emissive=(0, 0, 0), shade=(0.3, 0.3, 0.3), shift=0.0, toony=0.9,
             uv_transform=IDENTITY_UV_TRANSFORM) -> dict:
    """One material's Look columns."""
    return dict(base=base, alpha=(ALPHA_MODES[alpha], cutoff), texture=texture, emissive=emissive,
                shading=(SHADING[shading], float(double_sided), *shade, shift, toony, 0.0),
                uv_transform=uv_transform)


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """A closed box: 24 vertices (4 per face, so faces keep their own normals), 12 counter-clockwise triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, tris = [], []
    for axis in range(3):
        for sign in (-1, 1):
            u, v = [a for a in range(3) if a != axis]
            if sign < 0:
                u, v = v, u
            quad = []
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = np.where(sign > 0, hi, lo).astype(float)
                p[u] = (lo if a == 0 else hi)[u]
                p[v] = (lo if b == 0 else hi)[v]
                quad.append(p)
            n = np.zeros(3)
            n[axis] = sign
            q = np.array(quad)
            if np.dot(np.cross(q[1] - q[0], q[2] - q[0]), n) < 0:
                q = q[::-1]
            base = len(verts)
            verts.extend(q)
            tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.array(verts, np.float32), np.array(tris, np.uint32)


def part_character(vertices, triangles, triangle_material, materials: list[dict], uv=None,
                   textures: list[np.ndarray] = (), samplers=None, skeleton: Skeleton | None = None,
                   vertex_color=None, primitives=None, name: str = "parts") -> Character:
    """A character with a Look (and a Skeleton when given) from plain arrays.

    textures : list of (h, w, 4) uint8 images (rows top first); samplers : list of (mag, min, wrap_s, wrap_t)
    """
    v = np.asarray(vertices, np.float32)
    tris = np.asarray(triangles, np.uint32)
    n_m = len(materials)
    pixels = [np.asarray(t, np.uint8).reshape(-1, 4) for t in textures]
    info, first = [], 0
    for i, t in enumerate(textures):
        h, w = np.asarray(t).shape[:2]
        info.append([first, w, h, *(samplers[i] if samplers else (0, 0, 0, 0))])
        first += w * h
    look = Look(
        uv=np.zeros((len(v), 2), np.float32) if uv is None else np.asarray(uv, np.float32),
        base_color=np.array([m["base"] for m in materials], np.float32),
        emissive=np.array([m["emissive"] for m in materials], np.float32),
        alpha=np.array([m["alpha"] for m in materials], np.float32),
        shading=np.array([m["shading"] for m in materials], np.float32),
        texture=np.array([m["texture"] for m in materials], np.int32),
        uv_transform=np.array([m["uv_transform"] for m in materials], np.float32),
        texture_names=tuple(f"t{i}" for i in range(len(textures))),
        texture_info=np.array(info, np.int32).reshape(-1, 7),
        texture_pixels=np.vstack(pixels) if pixels else np.zeros((0, 4), np.uint8),
    )
    layout = None
    if primitives is not None:
        layout = Layout(tuple(f"m{i}" for i in range(len(primitives))), np.asarray(primitives, np.int64))
    return Character(
        name=name, units="m", vertices=v, triangles=tris,
        triangle_material=np.asarray(triangle_material, np.uint16),
        vertex_color=np.ones((len(v), 3), np.float32) if vertex_color is None else np.asarray(vertex_color,
                                                                                              np.float32),
        material_names=tuple(f"mat{i}" for i in range(n_m)),
        material_params=np.tile(np.array([0.1, 16.0, 0.0, 0.0], np.float32), (n_m, 1)),
        pivot=v.mean(axis=0).astype(np.float32), shape_names=(), delta_offsets=np.zeros(1, np.int64),
        delta_indices=np.zeros(0, np.uint32), delta_positions=np.zeros((0, 3), np.float32),
        delta_normals=np.zeros((0, 3), np.float32),
        metadata={"settings": {"source": {"format": "glb", "credits": "Test figure by Nobody, CC0"}}},
        look=look, skeleton=skeleton, layout=layout,
    )


def quad(z=0.0, size=1.0, reverse=False):
    """A square in the plane z facing +z (or -z with ``reverse``): vertices, triangles, uv (top-left origin)."""
    s = size / 2
    v = np.array([[-s, -s, z], [s, -s, z], [s, s, z], [-s, s, z]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # glTF: v = 0 at the image's top row
    t = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    return v, (t[:, ::-1].copy() if reverse else t), uv


def figure(morph: bool = True) -> Character:
    """A standing figure in metres: a body box (feet at y = 0) and a head box on top, a skeleton
    hips -> spine -> neck -> head; the head box follows the head bone, the body the hips; lit, opaque.
    With ``morph`` one shape ("mouthOpen") moves the head's front-face bottom vertices down."""
    bv, bt = box((-0.2, 0.0, -0.1), (0.2, 1.4, 0.1))
    hv, ht = box((-0.12, 1.5, -0.12), (0.12, 1.78, 0.12))
    v = np.vstack([bv, hv])
    t = np.vstack([bt, ht + len(bv)])
    names = ("hips", "spine", "neck", "head")
    parent = np.array([-1, 0, 1, 2], np.int32)
    heights = (0.9, 1.2, 1.42, 1.5)
    rest = np.tile(np.eye(4, dtype=np.float32), (4, 1, 1))
    prev = 0.0
    for j, h in enumerate(heights):
        rest[j, 1, 3] = h - prev
        prev = h
    nodes = np.zeros((len(v), 4), np.uint16)
    nodes[len(bv):, 0] = 3
    weights = np.zeros((len(v), 4), np.float32)
    weights[:, 0] = 1
    sk = Skeleton(names, parent, rest, nodes, weights, {"hips": 0, "spine": 1, "neck": 2, "head": 3})
    colors = np.vstack([np.tile([0.2, 0.4, 0.8], (len(bv), 1)), np.tile([0.9, 0.7, 0.6], (len(hv), 1))])
    c = part_character(v, t, np.zeros(len(t)), [material(shading="lit")], skeleton=sk, vertex_color=colors,
                       name="figure")
    if not morph:
        return c
    import dataclasses

    front_low = np.flatnonzero((np.abs(v[:, 2] - 0.12) < 1e-6) & (np.abs(v[:, 1] - 1.5) < 1e-6))
    return dataclasses.replace(
        c, shape_names=("mouthOpen",), delta_offsets=np.array([0, len(front_low)]),
        delta_indices=front_low.astype(np.uint32),
        delta_positions=np.tile(np.array([0, -0.08, 0.05], np.float32), (len(front_low), 1)),
        delta_normals=np.zeros((len(front_low), 3), np.float32))
