"""CpuDeformer against slow, obvious references."""

from __future__ import annotations

import numpy as np
import pytest
from small_characters import sphere_character

from facepuppet.runtime.deform import CpuDeformer
from facepuppet.runtime.geometry import vertex_normals


def reference_deform(character, weights):
    """Loop over shapes and sparse entries one by one, float64."""
    pos = character.vertices.astype(np.float64).copy()
    nrm = vertex_normals(character.vertices, character.triangles).astype(np.float64)
    for s, w in enumerate(weights):
        sl = character.shape_slice(s)
        for i, dp, dn in zip(character.delta_indices[sl], character.delta_positions[sl], character.delta_normals[sl]):
            pos[i] += w * dp
            nrm[i] += w * dn
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return pos, nrm


@pytest.mark.parametrize("weights", [[0.0, 0.0], [1.0, 0.0], [0.3, 0.7], [-0.1, 1.1]])
def test_matches_loop_reference(weights):
    c = sphere_character()
    pos, nrm = CpuDeformer(c).deform(np.array(weights, np.float32))
    ref_pos, ref_nrm = reference_deform(c, weights)
    assert pos.dtype == np.float32 and pos.shape == (c.n_vertices, 3)
    np.testing.assert_allclose(pos, ref_pos, atol=1e-5)
    used = np.unique(c.triangles)
    np.testing.assert_allclose(nrm[used], ref_nrm[used], atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(nrm[used], axis=1), 1.0, atol=1e-5)


def test_matches_dense_deltas_on_ict(ict_character):
    c = ict_character
    w = np.zeros(c.n_shapes, np.float32)
    w[[c.shape_names.index("jawOpen"), c.shape_names.index("eyeBlink_L")]] = [0.8, 0.5]
    pos, _ = CpuDeformer(c).deform(w)
    expected = c.vertices + np.tensordot(w, c.dense_deltas(), axes=1)
    np.testing.assert_allclose(pos, expected, atol=1e-4)


@pytest.mark.parametrize("shape", [0, 1])
def test_normals_at_a_single_shape_equal_normals_of_the_deformed_mesh(shape):
    c = sphere_character()
    w = np.zeros(c.n_shapes, np.float32)
    w[shape] = 1.0
    pos, nrm = CpuDeformer(c).deform(w)
    used = np.unique(c.triangles)
    expected = vertex_normals(pos, c.triangles)
    np.testing.assert_allclose(nrm[used], expected[used], atol=1e-5)


def test_deform_into_leaves_normals_unnormalised_and_positions_equal():
    c = sphere_character()
    d = CpuDeformer(c)
    w = np.array([0.5, 0.5], np.float32)
    raw = d.deform_into(w).copy()
    pos, nrm = d.deform(w)
    np.testing.assert_array_equal(raw[:, :3], pos)
    used = np.unique(c.triangles)
    unit = raw[used, 3:] / np.linalg.norm(raw[used, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(unit, nrm[used], atol=1e-6)


def test_weights_are_checked():
    d = CpuDeformer(sphere_character())
    with pytest.raises(ValueError, match=r"expected shape \(2,\).*got \(3,\)"):
        d.deform(np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        d.deform(np.array([np.nan, 0.0]))
