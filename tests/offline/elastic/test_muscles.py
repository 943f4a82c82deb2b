"""Muscles (§6): fall-offs and directions of a unit contraction."""

import numpy as np

from facepuppet.offline.elastic.muscles import Muscle, muscle_displacements


def test_linear_muscle_pulls_towards_attachment_inside_its_zone_only():
    m = Muscle("zyg", "linear", [[0, 0, 0], [2, 0, 0]], [2.0, 3.0, np.radians(30), 0.5])
    p = np.array([[2, 0, 0], [1, 0, 0], [2, 2, 0], [5, 0, 0], [2.5, 0, 0]], float)
    d = muscle_displacements([m], p)[0]
    np.testing.assert_allclose(d[0], [-0.5, 0, 0], atol=1e-6)  # at the insertion: full strength, towards a
    np.testing.assert_allclose(d[1], [-0.5 * np.cos(0.5 * np.pi / 2), 0, 0], atol=1e-6)  # eq. 10 inner fall-off
    assert np.abs(d[2]).max() == 0 and np.abs(d[3]).max() == 0  # outside the angle Ω, beyond Rf
    assert 0 < -d[4, 0] < 0.5


def test_sphincter_tightens_towards_its_centre():
    m = Muscle("oris", "sphincter", [[0, 0, 1], [0, 0, 0]], [2.0, 1.0, 0.3, 0])
    p = np.array([[1.0, 0, 1], [0, 0.5, 1], [3, 0, 1]], float)
    d = muscle_displacements([m], p)[0]
    assert d[0, 0] < 0 and d[1, 1] < 0 and np.abs(d[2]).max() == 0
    np.testing.assert_allclose(d[:, 2], 0)
