"""CpuDeformer against slow, obvious references."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.geometry import vertex_normals
from facepuppet.runtime.render.cpu_deform import CpuDeformer

from helpers.small_characters import sphere_character


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


def test_moving_spans_merge_short_gaps_only():
    from facepuppet.runtime.render.cpu_deform import moving_spans

    spans = moving_spans(np.array([3, 4, 5, 9, 10, 200, 201]), max_gap=4)
    np.testing.assert_array_equal(spans, [[3, 11], [200, 202]])     # gap of 3 merged, gap of 189 not
    np.testing.assert_array_equal(moving_spans(np.array([3, 9]), max_gap=0), [[3, 4], [9, 10]])
    assert moving_spans(np.array([], dtype=np.int64)).shape == (0, 2)


@pytest.mark.parametrize("n_active", [1, 5, 40, 57])
def test_both_regimes_match_dense_deltas_on_ict(ict_character, n_active):
    """Few active shapes take the saxpy branch, many the matrix product: both equal x0 + W D."""
    c = ict_character
    rng = np.random.default_rng(n_active)
    w = np.zeros(c.n_shapes, np.float32)
    w[rng.choice(c.n_shapes, n_active, replace=False)] = rng.uniform(-0.2, 1.0, n_active)
    d = CpuDeformer(c)
    assert 1 <= len(d.spans) < 64
    raw = d.deform_into(w)
    rest_normals = vertex_normals(c.vertices, c.triangles)
    expected_pos = c.vertices + np.tensordot(w, c.dense_deltas(), axes=1)
    expected_nrm = rest_normals + np.tensordot(w, c.dense_deltas(normals=True), axes=1)
    np.testing.assert_allclose(raw[:, :3], expected_pos, atol=2e-4)
    np.testing.assert_allclose(raw[:, 3:], expected_nrm, atol=2e-4)
    # a caller's own buffer, dirty beforehand, gets the same (still vertices included)
    mine = np.full((c.n_vertices, 6), 7.0, np.float32)
    np.testing.assert_array_equal(d.deform_into(w, mine), raw)
    # vertices no shape moves keep their rest position and normal exactly
    still = np.setdiff1d(np.arange(c.n_vertices), np.unique(c.delta_indices))
    np.testing.assert_array_equal(raw[still], np.c_[c.vertices, rest_normals][still])
