"""The framebuffer read as stored (RGBA, bottom row first) and finished elsewhere is the picture
``read_pixels`` gives, opaque and transparent, with MSAA and without."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.render.readback import finish_rgba
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.small_characters import sphere_character


@pytest.mark.gl
@pytest.mark.parametrize("transparent", [False, True])
@pytest.mark.parametrize("msaa", [0, 4])
def test_the_raw_read_finished_is_read_pixels(egl_ctx, transparent, msaa):
    sphere = sphere_character()
    r = FaceRenderer(egl_ctx, sphere, 40, 30, path="cpu", transparent=transparent, msaa=msaa)
    try:
        weights = np.zeros(sphere.n_shapes, np.float32)
        weights[0] = 0.7
        r.draw(weights)
        r.finish()
        raw = r.read_rgba()
        assert raw.shape == (30, 40, 4) and not raw.flags.writeable
        finished = finish_rgba(raw, transparent)
        expected = r.read_pixels()
        assert finished.shape == expected.shape == (30, 40, 4 if transparent else 3)
        np.testing.assert_array_equal(finished, expected)
        if transparent:
            assert finished[0, 0, 3] == 0 and (finished[:, :, 3] == 255).any()
    finally:
        r.close()
