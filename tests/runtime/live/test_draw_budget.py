"""DrawBudgetWatch on a real EGL renderer: MSAA off once when the draw keeps missing its budget share."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.live.draw_budget import DrawBudgetWatch
from facepuppet.runtime.live.loop import TickInfo
from facepuppet.runtime.render.quality import BUDGET_SHARE
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.small_characters import sphere_character

BUDGET_MS = 1000 / 60


def ticks(watch, draw_ms, n):
    info = TickInfo(watch.renderer)
    for _ in range(n):
        info.stamps = (0.0, 0.0, 1.0, 1.0, 1.0 + draw_ms / 1e3)  # map done at 1 s, the GPU done draw_ms later
        watch(info)


def test_over_budget_for_a_whole_window_turns_msaa_off_once_and_hands_on_the_new_framebuffer(egl_ctx):
    r = FaceRenderer(egl_ctx, sphere_character(), 96, 72, path="cpu", msaa=4)
    said, handed = [], []
    try:
        assert r.samples == 4
        old = r.fbo
        watch = DrawBudgetWatch(r, BUDGET_MS, said.append, [handed.append], window=40)
        ticks(watch, 0.9 * BUDGET_SHARE * BUDGET_MS, 60)   # within the share: nothing
        assert r.samples == 4 and not said
        ticks(watch, 1.5 * BUDGET_SHARE * BUDGET_MS, 15)   # a few slow ticks: the window's median still fits
        assert r.samples == 4 and not said
        ticks(watch, 1.5 * BUDGET_SHARE * BUDGET_MS, 25)   # most of the window slow
        assert r.samples == 0 and r.fbo is not old and handed == [r.fbo]
        assert len(said) == 1 and "MSAA off" in said[0] and "median of the last 40 ticks" in said[0]
        ticks(watch, 10 * BUDGET_MS, 200)                  # once only
        assert len(said) == 1 and handed == [r.fbo]
        r.draw(np.array([0.5, 0.0], np.float32))           # the renderer draws on into its new framebuffer
        r.finish()
        image = r.read_pixels()
        assert image.shape == (72, 96, 3) and image.std() > 5
        assert egl_ctx.error == "GL_NO_ERROR"
    finally:
        r.close()


def test_a_renderer_drawing_into_a_target_framebuffer_keeps_it(egl_ctx):
    target = egl_ctx.simple_framebuffer((64, 48))
    r = FaceRenderer(egl_ctx, sphere_character(), 64, 48, path="cpu", target_fbo=target)
    said = []
    try:
        assert r.set_msaa(4) is False and r.fbo is target
        watch = DrawBudgetWatch(r, BUDGET_MS, said.append, window=10)
        ticks(watch, 10 * BUDGET_MS, 30)
        assert r.fbo is target and not said  # no samples to lower: a window's are the window's
    finally:
        r.close()
        target.release()
