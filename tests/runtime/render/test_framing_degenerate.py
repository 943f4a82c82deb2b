"""Framing a character whose framed part is a point or a plane (glTF SimpleMorph: one flat triangle, each
target moving one vertex): the camera must still see it. ``contact-sheet`` on SimpleMorph failed with
"perspective: need 0 < near < far" before."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.renderer import FaceRenderer

pytestmark = pytest.mark.gl


def flat_triangle() -> Character:
    return Character(
        name="flat", units="m", vertices=np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0]], np.float32),
        triangles=np.array([[0, 1, 2]], np.uint32), triangle_material=np.zeros(1, np.uint16),
        vertex_color=np.ones((3, 3), np.float32), material_names=("m",),
        material_params=np.array([[0.1, 16, 0, 0]], np.float32), pivot=np.zeros(3, np.float32),
        shape_names=("up",), delta_offsets=np.array([0, 1]), delta_indices=np.array([2], np.uint32),
        delta_positions=np.array([[0, 0.5, 0]], np.float32), delta_normals=np.zeros((1, 3), np.float32))


@pytest.mark.parametrize("framing", ["face", "head", "body"])
def test_a_flat_character_with_one_moving_vertex_is_framed_and_seen(egl_ctx, framing):
    r = FaceRenderer(egl_ctx, flat_triangle(), 64, 64, path="cpu", framing=framing, log=lambda s: None,
                     background=(0.0, 0.0, 0.0))
    try:
        r.draw(np.zeros(1, np.float32))
        image = r.read_pixels()
    finally:
        r.close()
    lit = (image.max(axis=2) > 40).mean()
    assert 0.05 < lit < 0.95, f"the triangle covers {lit:.0%} of the frame"
