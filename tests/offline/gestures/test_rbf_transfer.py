"""Compact-support RBF detail transfer (Ju & Lee §5.2)."""

import numpy as np
import pytest

from facepuppet.offline.gestures.rbf_transfer import RBFTransfer, cubic_bspline


def test_kernel_is_the_cubic_bspline_with_compact_support():
    q = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 2.0])
    np.testing.assert_allclose(cubic_bspline(q), [1.0, 1 - 6 / 16 + 6 / 64, 0.25, 2 * 0.25 ** 3, 0.0, 0.0])


def test_interpolates_at_the_markers_and_is_local():
    rng = np.random.default_rng(0)
    centres = rng.uniform(-5, 5, size=(30, 3))
    values = rng.normal(size=(30, 2))
    rbf = RBFTransfer(radius=3.0).fit(centres, values)
    np.testing.assert_allclose(rbf.transform(centres), values, atol=1e-9)
    far = np.array([[50.0, 0.0, 0.0]])
    np.testing.assert_array_equal(rbf.transform(far), 0.0)


def test_dense_reference_matches():
    rng = np.random.default_rng(1)
    c, v, x = rng.uniform(0, 4, (12, 3)), rng.normal(size=(12, 1)), rng.uniform(0, 4, (7, 3))
    rbf = RBFTransfer(radius=2.5).fit(c, v)
    phi = cubic_bspline(np.linalg.norm(c[:, None] - c[None], axis=2) / 2.5)
    w = np.linalg.solve(phi, v)
    ref = cubic_bspline(np.linalg.norm(x[:, None] - c[None], axis=2) / 2.5) @ w
    np.testing.assert_allclose(rbf.transform(x), ref, atol=1e-9)


def test_unfitted_and_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="fit"):
        RBFTransfer(1.0).transform(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="centres"):
        RBFTransfer(1.0).fit(np.zeros((4, 2)), np.zeros(4))
