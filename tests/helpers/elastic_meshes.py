"""Small meshes for the elastic-model tests: a bumpy height-field "face" grid and helpers."""

from __future__ import annotations

import numpy as np

from facepuppet.offline.elastic.control_points import ControlPoints


def grid(n: int = 13, size: float = 10.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A gently curved n×n grid in the xy plane facing +z: vertices (n², 3) float64, triangles int64."""
    x, y = np.meshgrid(np.linspace(-size / 2, size / 2, n), np.linspace(-size / 2, size / 2, n))
    rng = np.random.default_rng(seed)
    z = 3.0 - 0.04 * (x**2 + y**2) + 0.05 * rng.standard_normal(x.shape)
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return v, tris


def nearest(v: np.ndarray, x: float, y: float) -> int:
    return int(np.argmin(np.hypot(v[:, 0] - x, v[:, 1] - y)))


def face_points(v: np.ndarray) -> ControlPoints:
    """Named control points on the grid with every role the method needs."""
    spots = {
        "nose_tip": (0, 0), "forehead": (0, 2.5), "eye_inner_L": (0.9, 1.3), "eye_inner_R": (-0.9, 1.3),
        "mouth_corner_L": (1.2, -1.6), "mouth_corner_R": (-1.2, -1.6), "chin": (0, -2.6), "cheek_L": (2, -0.5),
    }
    return ControlPoints(tuple(spots), np.array([nearest(v, *xy) for xy in spots.values()], np.int64))
