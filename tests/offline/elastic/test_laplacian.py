"""Sparse mesh operators against dense references built by loops."""

import numpy as np
import pytest

from facepuppet.offline.elastic.laplacian import (
    bilaplacian,
    components,
    cotangent_laplacian,
    vertex_areas,
    vertex_gradients,
)
from helpers.elastic_meshes import grid


def dense_cotangent(v, tris):
    n = len(v)
    k = np.zeros((n, n))
    for t in tris:
        for c in range(3):
            o, i, j = t[c], t[(c + 1) % 3], t[(c + 2) % 3]
            a, b = v[i] - v[o], v[j] - v[o]
            cross = np.linalg.norm(np.cross(a, b))
            if cross < 1e-12:
                continue
            w = 0.5 * np.dot(a, b) / cross
            k[i, j] -= w
            k[j, i] -= w
            k[i, i] += w
            k[j, j] += w
    return k


def dense_areas(v, tris):
    m = np.zeros(len(v))
    for t in tris:
        area = 0.5 * np.linalg.norm(np.cross(v[t[1]] - v[t[0]], v[t[2]] - v[t[0]]))
        for i in t:
            m[i] += area / 3
    return m


def test_cotangent_laplacian_and_mass_match_loops():
    v, tris = grid(6)
    k = cotangent_laplacian(v, tris).toarray()
    np.testing.assert_allclose(k, dense_cotangent(v, tris), atol=1e-12)
    np.testing.assert_allclose(vertex_areas(v, tris), dense_areas(v, tris), rtol=1e-12)
    m = dense_areas(v, tris)
    np.testing.assert_allclose(bilaplacian(v, tris).toarray(), k @ np.diag(1 / m) @ k, atol=1e-9)
    np.testing.assert_allclose(k.sum(axis=1), 0, atol=1e-12)


def test_degenerate_triangle_and_isolated_vertex_are_tolerated():
    v, tris = grid(4)
    v = np.vstack([v, v[0], [50.0, 50.0, 50.0]])  # a duplicate of vertex 0 and an isolated vertex
    tris = np.vstack([tris, [[0, 1, len(v) - 2]]])  # zero-area triangle
    k = cotangent_laplacian(v, tris).toarray()
    assert np.isfinite(k).all()
    np.testing.assert_allclose(k, dense_cotangent(v, tris), atol=1e-12)
    assert (vertex_areas(v, tris) > 0).all()


def test_gradient_of_a_linear_function_is_exact():
    v, tris = grid(7)
    v[:, 2] = 0.0  # flat: a linear function has the same gradient in every triangle
    gx, gy, gz = vertex_gradients(v, tris)
    f = 2 * v[:, 0] - 3 * v[:, 1]
    g = np.stack([gx @ f, gy @ f, gz @ f], 1)
    np.testing.assert_allclose(g, np.tile([2.0, -3.0, 0.0], (len(v), 1)), atol=1e-9)


def test_components_label_disconnected_parts():
    v, tris = grid(4)
    count, labels = components(2 * len(v), np.vstack([tris, tris + len(v)]))
    assert count == 2 and labels[0] != labels[len(v)]


def test_bad_mesh_is_named():
    with pytest.raises(ValueError, match="triangles: indices must lie in"):
        cotangent_laplacian(np.zeros((3, 3)), [[0, 1, 5]])
