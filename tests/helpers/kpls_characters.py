"""Tiny blendshape characters for the retargeting tests: a bumpy sphere with named smooth shapes."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas

SHAPES = ("jawOpen", "mouthSmileLeft", "mouthSmileRight", "eyeBlinkLeft", "eyeBlinkRight",
          "browInnerUp", "mouthPucker", "cheekPuff")


def sphere(n_lat: int = 12, n_lon: int = 16):
    lat = np.linspace(0.15, np.pi - 0.15, n_lat)
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.sin(la) * np.sin(lo), np.cos(la), np.sin(la) * np.cos(lo)], -1).reshape(-1, 3)
    tris = []
    for i in range(n_lat - 1):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            tris += [(a, a + n_lon, b + n_lon), (a, b + n_lon, b)]
    return v, np.array(tris, np.uint32)


def bump_character(scale=(1.0, 1.0, 1.0), amplitude: float = 1.0, names=SHAPES, seed: int = 0,
                   name: str = "bumps") -> Character:
    """Sphere scaled by ``scale``; shape i moves a Gaussian patch around a fixed centre along a fixed direction."""
    v, tris = sphere()
    rng = np.random.default_rng(seed)
    centres = v[rng.choice(len(v), len(names), replace=False)]
    dense = []
    for i, c in enumerate(centres):
        fall = np.exp(-((v - c) ** 2).sum(1) / 0.15)[:, None]
        direction = np.array([np.cos(i), np.sin(1.7 * i), 0.5])
        dense.append(0.2 * amplitude * fall * direction)
    dense = np.stack(dense) * np.asarray(scale)
    offsets, indices, positions = sparse_deltas(dense.astype(np.float32), tolerance=1e-6)
    return Character(
        name=name, units="cm", vertices=(v * np.asarray(scale)).astype(np.float32), triangles=tris,
        triangle_material=np.zeros(len(tris), np.uint16), vertex_color=np.full((len(v), 3), 0.5, np.float32),
        material_names=("skin",), material_params=np.array([[0.1, 20, MATERIAL_KINDS["skin"], 0]], np.float32),
        pivot=np.zeros(3, np.float32), shape_names=tuple(names), delta_offsets=offsets, delta_indices=indices,
        delta_positions=positions, delta_normals=np.zeros_like(positions),
    )
