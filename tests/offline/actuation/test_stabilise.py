"""Kabsch and head stabilisation."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.geometry import euler_to_quat, quat_to_matrix

from facepuppet.offline.actuation.stabilise import find_head_markers, kabsch, stabilise


def test_kabsch_recovers_a_known_rigid_motion():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(6, 3))
    r_true = quat_to_matrix(euler_to_quat(0.3, -0.2, 0.5)).astype(np.float64)
    t_true = np.array([1.0, -2.0, 0.5])
    q = (p - t_true) @ r_true          # q = R^T (p - t): R q + t = p
    r, t = kabsch(p, q)
    np.testing.assert_allclose(r, r_true, atol=1e-6)
    np.testing.assert_allclose(t, t_true, atol=1e-6)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # batched: a stack of frames gives the same per-frame answer
    rb, tb = kabsch(np.stack([p, p]), np.stack([q, p]))
    np.testing.assert_allclose(rb[0], r_true, atol=1e-6)
    np.testing.assert_allclose(rb[1], np.eye(3), atol=1e-9)


def _take():
    rng = np.random.default_rng(1)
    neutral = rng.normal(size=(8, 3)) * 5
    n = 50
    markers = np.repeat(neutral[None], n, axis=0)
    markers[:, 5:, 1] += np.sin(np.linspace(0, 6, n))[:, None] * [1.0, -2.0, 3.0]   # markers 5.. deform
    rot = np.stack([quat_to_matrix(euler_to_quat(0.1 * np.sin(i / 5), 0.05 * i / n, 0.0)) for i in range(n)])
    moved = markers @ np.swapaxes(rot, 1, 2) + np.linspace(0, 1, n)[:, None, None]
    return markers, moved


def test_stabilise_removes_head_motion_and_finds_rigid_markers():
    markers, moved = _take()
    names = [f"m{i}" for i in range(8)]
    assert set(find_head_markers(moved, 4)) <= {0, 1, 2, 3, 4}
    out = stabilise(moved, names, head_markers=["m0", "m1", "m2", "m3"])
    assert not out.head_fixed and out.max_angle_deg > 3
    np.testing.assert_allclose(out.markers, markers, atol=1e-4)   # reference frame 0 has no rotation
    again = stabilise(out.markers, names, head_markers=[0, 1, 2, 3])
    assert again.head_fixed and "already head-fixed" in again.summary()


def test_stabilise_bad_inputs():
    markers, moved = _take()
    with pytest.raises(ValueError, match="no marker named 'nose'"):
        stabilise(moved, [f"m{i}" for i in range(8)], head_markers=["nose", "m1", "m2"])
    with pytest.raises(ValueError, match="at least 3 distinct markers"):
        stabilise(moved, [f"m{i}" for i in range(8)], head_markers=[0, 1])
