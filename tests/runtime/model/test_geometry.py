"""The one smoothstep: edges either way round, floats stay floats, arrays keep their shape."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.geometry import smoothstep


def smoothstep_by_cases(e0: float, e1: float, x: float) -> float:
    """The obvious reference: below, between and above the edges, one case at a time."""
    t = (x - e0) / (e1 - e0)
    if t <= 0.0:
        return 0.0
    if t >= 1.0:
        return 1.0
    return 3.0 * t**2 - 2.0 * t**3


def test_smoothstep_matches_the_case_by_case_reference():
    xs = np.linspace(-2.0, 3.0, 101)
    for e0, e1 in ((0.0, 1.0), (-1.5, 2.5), (2.6, -1.6), (0.1, -0.06)):
        got = smoothstep(e0, e1, xs)
        assert got.shape == xs.shape and got.dtype == np.float64
        np.testing.assert_allclose(got, [smoothstep_by_cases(e0, e1, x) for x in xs], rtol=0, atol=1e-15)
        assert smoothstep(e0, e1, e0) == 0.0 and smoothstep(e0, e1, e1) == 1.0


def test_a_float_gives_the_same_float_as_its_array():
    for x in (-0.25, 0.0, 0.3, 0.5, 0.999, 1.0, 7.0):
        got = smoothstep(0.0, 1.0, x)
        assert type(got) is float
        assert got == smoothstep(0.0, 1.0, np.array([x]))[0]
    grid = smoothstep(6.0, 4.5, np.arange(12.0).reshape(3, 4))
    assert grid.shape == (3, 4) and grid[0, 0] == 1.0 and grid[-1, -1] == 0.0
