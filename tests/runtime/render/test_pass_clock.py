"""PassClock on a real EGL context: every pass of a frame named and timed, the picture unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.render.pass_clock import PassClock
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.small_characters import sphere_character

W, H = 160, 120


def frame(ctx, renderer, clock=None):
    renderer.prepare(np.array([0.5, 0.0], np.float32))
    if clock is None:
        renderer.submit()
        renderer.finish()
        return renderer.read_pixels()
    clock.start()
    renderer.submit(clock)
    renderer.resolve(clock)
    times = clock.stop()
    return renderer.read_pixels(), times


@pytest.mark.parametrize("msaa", [0, 4])
def test_finish_mode_names_every_pass_and_the_picture_is_the_unclocked_one(egl_ctx, msaa):
    r = FaceRenderer(egl_ctx, sphere_character(), W, H, path="cpu", msaa=msaa)
    try:
        plain = frame(egl_ctx, r)
        clock = PassClock(egl_ctx)
        timed, times = frame(egl_ctx, r, clock)
        expected = ["setup", "clear", "opaque", "blended"] + (["resolve"] if msaa else [])
        assert list(times) == expected
        assert all(np.isfinite(v) and v >= 0 for v in times.values())
        assert clock.frames == [times]
        np.testing.assert_array_equal(plain, timed)
        assert egl_ctx.error == "GL_NO_ERROR"
    finally:
        r.close()


def test_query_mode_gives_one_time_per_pass_in_order_frame_after_frame(egl_ctx):
    r = FaceRenderer(egl_ctx, sphere_character(), W, H, path="gpu", msaa=4)
    try:
        clock = PassClock(egl_ctx, "query")
        for _ in range(3):  # the query objects are reused from frame to frame
            _, times = frame(egl_ctx, r, clock)
            assert list(times) == ["setup", "clear", "opaque", "blended", "resolve"]
            assert all(v >= 0 for v in times.values())
        assert len(clock.frames) == 3
        assert egl_ctx.error == "GL_NO_ERROR"
    finally:
        r.close()


def test_an_unknown_mode_is_refused(egl_ctx):
    with pytest.raises(ValueError, match="mode"):
        PassClock(egl_ctx, "stopwatch")
