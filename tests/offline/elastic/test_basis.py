"""Elastic basis: exact at handles, zero in the fixed region, compact form, bad inputs."""

import numpy as np
import pytest

from facepuppet.offline.elastic.basis import ElasticBasis, fixed_region
from facepuppet.offline.elastic.laplacian import bilaplacian
from facepuppet.offline.elastic.params import ExpressionFit
from helpers.elastic_meshes import face_points, grid


@pytest.fixture(scope="module")
def fitted():
    v, tris = grid(15)
    points = face_points(v)
    fixed = fixed_region(v, v[points.vertex("nose_tip")], v[points.vertex("forehead")], ratio=1.6)
    return v, tris, points, fixed, ElasticBasis(k=4).fit(v, tris, points.vertices, fixed, points.names)


def test_basis_is_exact_at_handles_and_zero_in_the_fixed_region(fitted):
    v, tris, points, fixed, basis = fitted
    assert fixed.sum() > 20  # the rule leaves a real fixed border on this grid
    rng = np.random.default_rng(1)
    u = rng.standard_normal((len(points.names), 3))
    d = basis.displace(u)
    np.testing.assert_allclose(d[points.vertices], u, atol=1e-12)
    assert np.abs(d[fixed]).max() == 0.0
    # Compact form keeps both properties: a handle's own weight is its largest.
    dk = basis.displace(u, compact=True)
    np.testing.assert_allclose(dk[points.vertices], u, atol=1e-6)
    assert np.abs(dk[fixed]).max() == 0.0


def test_basis_solves_the_bilaplacian_on_free_vertices(fitted):
    v, tris, points, fixed, basis = fitted
    free = np.ones(len(v), bool)
    free[fixed] = False
    free[points.vertices] = False
    residual = bilaplacian(v, tris)[free] @ basis.weights_  # Yano & Harada eq. 4
    assert np.abs(residual).max() < 1e-8 * np.abs(bilaplacian(v, tris)).max()


def test_compact_rows_keep_their_sum(fitted):
    *_, basis = fitted
    np.testing.assert_allclose(basis.compact_weights_.sum(1), basis.weights_.sum(1), atol=1e-5)
    assert basis.compact_indices_.shape == (len(basis.weights_), 4)


def test_expression_from_known_control_displacements_is_recovered(fitted):
    v, tris, points, fixed, basis = fitted
    u = np.random.default_rng(2).standard_normal((2, len(points.names), 3))
    deltas = np.stack([basis.displace(s, compact=True) for s in u])
    fit = ExpressionFit().fit(basis.compact_matrix(), deltas)  # Yano & Harada eq. 6
    np.testing.assert_allclose(fit.params_, u, atol=1e-5)
    assert np.nanmax(fit.relative_) < 1e-5


def test_control_point_in_the_fixed_region_is_refused(fitted):
    v, tris, points, fixed, _ = fitted
    handles = points.vertices.copy()
    handles[-1] = np.flatnonzero(fixed)[0]
    with pytest.raises(ValueError, match="'cheek_L'.*lies in the fixed region"):
        ElasticBasis().fit(v, tris, handles, fixed, points.names)


def test_duplicate_handles_are_refused(fitted):
    v, tris, points, fixed, _ = fitted
    handles = points.vertices.copy()
    handles[1] = handles[0]
    with pytest.raises(ValueError, match="duplicate handles on one vertex: 'nose_tip'.*'forehead'"):
        ElasticBasis().fit(v, tris, handles, fixed, points.names)


def test_disconnected_handle_free_component(fitted):
    v, tris, points, fixed, _ = fitted
    v2 = np.vstack([v, v + [30.0, 0, 0]])
    t2 = np.vstack([tris, tris + len(v)])
    f2 = np.concatenate([fixed, np.zeros(len(v), bool)])
    held = ElasticBasis().fit(v2, t2, points.vertices, f2)  # default: held fixed, reported
    assert held.detached_mask_[len(v):].all() and np.abs(held.weights_[len(v):]).max() == 0
    with pytest.raises(ValueError, match="component 1 .* disconnected from every control point"):
        ElasticBasis(free_components=[1]).fit(v2, t2, points.vertices, f2)
