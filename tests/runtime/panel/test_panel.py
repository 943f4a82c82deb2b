"""The panel driven headless: a real EGL context, the real renderer and pipeline, events through ImGui's IO."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.small_characters import sphere_character

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

from facepuppet.runtime.panel.channels import METER_COLOURS  # noqa: E402
from facepuppet.runtime.panel.desk import DeskPanel  # noqa: E402

pytestmark = pytest.mark.gl
W, H, FPS = 480, 640, 30.0
CHANNELS = ("jawOpen", "eyeBlinkLeft", "puff")


def _frames(jaw, n=20):
    return [Frame(t=i / FPS, source="test", channels=CHANNELS, weights=np.array([jaw, 0.2, 0.5])) for i in range(n)]


class _Run:
    """The sphere head, a LivePipeline and a DeskPanel in one FrameLoop on recorded time."""

    def __init__(self, ctx, visible=True, panel=True):
        self.character = sphere_character()
        self.renderer = FaceRenderer(ctx, self.character, W, H, path="gpu", log=lambda s: None)
        self.pipeline = LivePipeline()
        self.now = 0.0
        self.panel = None
        if panel:
            self.panel = DeskPanel(ctx, self.renderer.fbo, W, H, pipeline=self.pipeline, character=self.character,
                                   names=self.character.shape_names, input_kind="test", address="127.0.0.1:1",
                                   visible=visible, clock=lambda: self.now)
        self.events = {}  # tick index -> callable run before that tick's panel draw

    def _hook(self, info):
        self.now += 1.0 / FPS
        action = self.events.get(info.k + 1)
        if action is not None:
            action()

    def run(self, frames):
        loop = FrameLoop(self.character.shape_names, self.renderer, RecordedClock(), fps=FPS, log=lambda s: None,
                         stages=[self.pipeline], observers=[self._hook],
                         overlays=() if self.panel is None else (self.panel.overlay,))
        loop.run(ReplaySource(frames), duration=(len(frames) - 1) / FPS)
        return self.renderer.read_pixels()

    def close(self):
        if self.panel is not None:
            self.panel.close()
        self.renderer.close()


def _click(panel, x, y, down):
    panel.io.add_mouse_pos_event(float(x), float(y))
    panel.io.add_mouse_button_event(0, down)


def test_dragging_a_filter_slider_reaches_the_pipeline(egl_ctx):
    run = _Run(egl_ctx)
    try:
        run.run(_frames(0.4, 6))  # lay the panel out: where the slider is
        x0, y0, x1, y1 = run.panel.rects["filter.mouth.beta"]
        before = run.pipeline.config.filters["mouth"]
        assert before.beta == pytest.approx(0.4)
        x, y = x0 + 0.9 * (x1 - x0), (y0 + y1) / 2  # 90 % along a 0..5 slider: beta about 4.5
        run.events = {2: lambda: _click(run.panel, x, y, True), 5: lambda: _click(run.panel, x, y, False)}
        run.run(_frames(0.4, 10))
        after = run.pipeline.config.filters["mouth"]
        assert 4.0 < after.beta < 5.0
        assert after.min_cutoff == before.min_cutoff  # only what was dragged
        assert run.pipeline.config.filters["eyes"] == before.__class__(3.0, 1.5)
        # the running filter took it: jawOpen is a mouth channel, eyeBlinkLeft an eye channel
        cs = run.pipeline._cs
        assert cs.weights.beta[0] == pytest.approx(after.beta)
        assert cs.weights.beta[1] == pytest.approx(1.5)
        assert run.panel.edits >= 1
    finally:
        run.close()


def test_calibrate_button_captures_a_neutral_and_clear_drops_it(egl_ctx):
    run = _Run(egl_ctx)
    try:
        run.run(_frames(0.4, 6))
        cx, cy = _centre(run.panel.rects["calibrate"])
        run.events = {2: lambda: _click(run.panel, cx, cy, True), 4: lambda: _click(run.panel, cx, cy, False)}
        run.run(_frames(0.4, 30))  # 1 s of frames: the 0.5 s capture completes
        assert run.pipeline.counters["calibrations"] == 1
        np.testing.assert_allclose(run.pipeline.neutral_weights, [0.4, 0.2, 0.5])
        kx, ky = _centre(run.panel.rects["clear"])
        run.events = {2: lambda: _click(run.panel, kx, ky, True), 4: lambda: _click(run.panel, kx, ky, False)}
        run.run(_frames(0.4, 8))
        assert run.pipeline.neutral_weights is None
    finally:
        run.close()


def _centre(rect):
    return (rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2


def _meter_pixels(image, rect, colour):
    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    patch = image[y0:y1, x0:x1, :3].astype(int)
    want = np.round(np.array(colour[:3]) * 255).astype(int)
    return int((np.abs(patch - want).max(axis=2) <= 3).sum()), patch.shape[0] * patch.shape[1]


def test_a_meter_bar_grows_with_its_channel_in_the_pixels(egl_ctx):
    counts = {}
    for jaw in (0.1, 0.9):
        run = _Run(egl_ctx)
        try:
            image = run.run(_frames(jaw, 40))  # settled: the filter's output is the constant input
            for j in range(3):  # raw, filtered, mapped meters of jawOpen (the first row)
                counts[jaw, j] = _meter_pixels(image, run.panel.rects[f"meter.0.{j}"], METER_COLOURS[j])
        finally:
            run.close()
    for j in range(3):
        (low, area), (high, _) = counts[0.1, j], counts[0.9, j]
        assert low > 0.03 * area  # a sliver of bar at 0.1
        assert high > 5 * low  # most of the meter at 0.9
        assert high < area


def test_ticks_faster_than_rebuild_hz_draw_the_last_imgui_frame_again_pixel_for_pixel(egl_ctx):
    images = {}
    for step in (1.0 / FPS, 1.0 / 240):  # 30 ticks/s: an ImGui frame each tick; 240/s: one every fourth or so
        run = _Run(egl_ctx)
        reused = []  # the panel's count of redrawn ticks, after each tick

        def hook(info, run=run, step=step, reused=reused):
            run.now += step
            reused.append(run.panel.reused)
        run._hook = hook
        try:
            images[step] = run.run(_frames(0.6, 12))
            panel = run.panel
            ticks = panel.draw_sketch.n
            assert ticks == 12
            if step < 1.0 / 60:
                assert panel.reused >= 6 and panel.live_builds == ticks - panel.reused
                assert reused[-1] == reused[-2] + 1  # the image read is of a redrawn tick
            else:
                assert panel.reused == 0
        finally:
            run.close()
    # every tick drew the panel: the last frame (a redraw of an ImGui frame, or a new one of the same values)
    # shows the same panel as a run that built a frame each tick
    np.testing.assert_array_equal(images[1.0 / 240], images[1.0 / FPS])


def test_the_hidden_panel_leaves_the_frame_as_it_was(egl_ctx):
    images = {}
    for name, kwargs in {"none": {"panel": False}, "hidden": {"visible": False}, "shown": {}}.items():
        run = _Run(egl_ctx, **kwargs)
        try:
            images[name] = run.run(_frames(0.6, 6))
        finally:
            run.close()
    np.testing.assert_array_equal(images["hidden"], images["none"])
    assert (images["shown"] != images["none"]).any(axis=2).mean() > 0.05  # the shown panel is really drawn


def test_without_imgui_bundle_the_panel_says_how_to_install_it(monkeypatch):
    from facepuppet.runtime.panel import PanelUnavailable, load_imgui

    monkeypatch.setitem(sys.modules, "imgui_bundle", None)  # an import of it now fails as if not installed
    with pytest.raises(PanelUnavailable, match=r"facepuppet\[panel\]"):
        load_imgui()


def test_the_mapped_meter_of_an_unsided_channel_reads_the_shape_the_map_drives(egl_ctx):
    fbo = egl_ctx.simple_framebuffer((64, 64))
    panel = DeskPanel(egl_ctx, fbo, 64, 64, names=("jawOpen", "browInnerUp_L", "browInnerUp_R"))
    try:  # browInnerUp has no shape of its name on this rig; the channel map sends it to both sides
        assert list(panel._mapped_index(("browInnerUp", "jawOpen", "tongueOut"))) == [1, 0, -1]
    finally:
        panel.close()
        fbo.release()
