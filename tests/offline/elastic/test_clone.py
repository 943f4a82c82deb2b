"""Cloning (§5) between meshes related by a known similarity transform; correspondence helpers."""

import numpy as np
import pytest

from facepuppet.offline.elastic.basis import ElasticBasis, fixed_region
from facepuppet.offline.elastic.clone import clone_parameters
from facepuppet.offline.elastic.control_points import (
    ControlPoints,
    propose_control_points,
    read_control_points,
    similarity_transform,
    write_control_points,
)
from helpers.elastic_meshes import face_points, grid


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_clone_under_similarity_reproduces_transformed_displacements():
    v, tris = grid(15)
    points = face_points(v)
    scale, q, shift = 2.5, rotation([0.3, 1.0, -0.2], 0.7), np.array([4.0, -1.0, 7.0])
    target = scale * v @ q.T + shift
    u = np.random.default_rng(3).standard_normal((3, len(points.names), 3))
    cloned = clone_parameters(u, v[points.vertices], points, target[points.vertices], points)
    np.testing.assert_allclose(cloned, scale * u @ q.T, atol=1e-5)
    # The target's own basis then moves its whole surface as the transformed source would.
    fs = fixed_region(v, v[points.vertex("nose_tip")], v[points.vertex("forehead")], 1.6)
    ft = fixed_region(target, target[points.vertex("nose_tip")], target[points.vertex("forehead")], 1.6)
    assert (fs == ft).all()
    src = ElasticBasis().fit(v, tris, points.vertices, fs).displace(u[0])
    tgt = ElasticBasis().fit(target, tris, points.vertices, ft).displace(cloned[0])
    np.testing.assert_allclose(tgt, scale * src @ q.T, atol=1e-4)


def test_clone_needs_matching_names():
    v, _ = grid(9)
    points = face_points(v)
    other = ControlPoints(points.names[::-1], points.vertices[::-1])
    with pytest.raises(ValueError, match="correspondences: target control points must carry the source's names"):
        clone_parameters(np.zeros((1, len(points.names), 3)), v[points.vertices], points, v[points.vertices], other)


def test_proposer_finds_the_transformed_points_and_file_round_trip(tmp_path):
    v, _ = grid(15)
    points = face_points(v)
    q = rotation([0, 1, 0], 0.4)
    target = 0.5 * v @ q.T + 1.0
    anchors = [points.index(n) for n in ("eye_inner_L", "eye_inner_R", "nose_tip", "chin")]
    proposed = propose_control_points(
        v[points.vertices], v[points.vertices][anchors], target, target[points.vertices][anchors],
        np.arange(len(v)), points.names,
    )
    np.testing.assert_array_equal(proposed.vertices, points.vertices)
    s, r, t = similarity_transform(v, target)
    assert abs(s - 0.5) < 1e-9 and np.allclose(r, q)
    path = write_control_points(tmp_path / "points.json", proposed)
    back = read_control_points(path, len(v))
    assert back.names == proposed.names and (back.vertices == proposed.vertices).all()
    (tmp_path / "bad.json").write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="bad.json: format: expected 'facepuppet-control-points'"):
        read_control_points(tmp_path / "bad.json")
    with pytest.raises(ValueError, match="vertex indices must lie in"):
        read_control_points(path, 5)
