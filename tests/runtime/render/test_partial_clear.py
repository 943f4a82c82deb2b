"""A frame clears only the screen rectangle the character can cover in it and in the frame before; the
pictures must be exactly those of clearing everything, frame after frame, while the head turns, moves
and the shapes swing (real EGL, both deformation paths, MSAA on)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.geometry import euler_to_quat
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.part_characters import figure
from helpers.small_characters import grid_face, sphere_character

pytestmark = pytest.mark.gl


def frames(ctx, character, path, full: bool, framing: str, moves):
    r = FaceRenderer(ctx, character, 160, 120, path=path, msaa=4, framing=framing, log=lambda s: None)
    if full:
        r.fbo  # noqa: B018 -- taken (as a panel would): every frame clears all of it
    out = []
    try:
        for weights, rotation, translation in moves:
            r.draw(np.asarray(weights, np.float32), head_rotation=rotation, head_translation=translation)
            out.append(r.read_pixels())
        return out, r._last_rect
    finally:
        r.close()


def swings(n_shapes: int, n: int = 14, scale: float = 1.0):
    """A sequence: shapes on and off (to 1.0), the head turning 35 degrees each way and moving sideways."""
    out = []
    for i in range(n):
        w = np.zeros(n_shapes)
        w[i % n_shapes] = 1.0 if i % 3 else 0.0
        yaw = np.radians(35) * np.sin(i * 1.3)
        rotation = euler_to_quat(yaw, np.radians(10) * np.cos(i), 0.0)
        translation = np.array([0.25 * np.sin(i * 0.7), 0.0, 0.0]) * scale
        out.append((w, rotation, translation))
    out.append((np.zeros(n_shapes), None, None))  # and back to rest: nothing may stay behind
    return out


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_partial_clears_draw_exactly_what_full_clears_draw_on_a_skinned_figure(egl_ctx, path):
    c = figure()
    moves = swings(c.n_shapes, scale=0.5)
    partial, rect = frames(egl_ctx, c, path, False, "body", moves)
    full, none = frames(egl_ctx, c, path, True, "body", moves)
    assert rect is not None and none is None  # the first cleared only a rectangle, the second all
    assert rect[2] * rect[3] < 160 * 120     # and that rectangle is not the whole frame
    for i, (a, b) in enumerate(zip(partial, full)):
        assert np.array_equal(a, b), f"frame {i} differs from a fully cleared one"


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_partial_clears_draw_exactly_what_full_clears_draw_on_a_morphing_head(egl_ctx, path):
    c = sphere_character(with_hidden=False)
    moves = swings(c.n_shapes, scale=1.5)
    partial, rect = frames(egl_ctx, c, path, False, "body", moves)
    full, _ = frames(egl_ctx, c, path, True, "body", moves)
    for i, (a, b) in enumerate(zip(partial, full)):
        assert np.array_equal(a, b), f"frame {i} differs from a fully cleared one"


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_a_shape_that_moves_past_the_rest_outline_leaves_nothing_behind(egl_ctx, path):
    c = grid_face()  # a thin sheet: its rest box is tight, so jawOpen's drop reaches past it
    jaw = c.shape_names.index("jawOpen")
    on, off = np.zeros(c.n_shapes), np.zeros(c.n_shapes)
    on[jaw] = 3.0  # an over-driven shape (a tracker's gain): three times the modelled drop
    moves = [(off, None, None), (on, None, None), (off, None, None), (on, None, None), (off, None, None)]
    partial, rect = frames(egl_ctx, c, path, False, "body", moves)
    full, _ = frames(egl_ctx, c, path, True, "body", moves)
    assert not np.array_equal(full[0], full[1])  # the shape does change the picture
    for i, (a, b) in enumerate(zip(partial, full)):
        assert np.array_equal(a, b), f"frame {i} differs from a fully cleared one"
