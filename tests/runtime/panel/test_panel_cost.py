"""The panel's cheaper frame, driven headless (real EGL context, renderer and pipeline, events through ImGui's IO):
the meters are rectangles whose lengths are the values, settings sections out of view are not built (and come
back, clickable, when scrolled into view), the selected channel's numbers are shown."""

from __future__ import annotations

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
W, H, FPS = 480, 640, 30.0  # one window (too narrow for two): the lower settings are below its bottom
CHANNELS = ("jawOpen", "eyeBlinkLeft", "puff")


def _frames(jaw, n):
    return [Frame(t=i / FPS, source="test", channels=CHANNELS, weights=np.array([jaw, 0.2, 0.5])) for i in range(n)]


class _Run:
    def __init__(self, ctx):
        self.character = sphere_character()
        self.renderer = FaceRenderer(ctx, self.character, W, H, path="gpu", log=lambda s: None)
        self.pipeline = LivePipeline(log=lambda s: None)
        self.now = 0.0
        self.panel = DeskPanel(ctx, self.renderer.fbo, W, H, pipeline=self.pipeline, character=self.character,
                               names=self.character.shape_names, input_kind="test", address="127.0.0.1:1",
                               clock=lambda: self.now)
        self.events = {}

    def _hook(self, info):
        self.now += 1.0 / FPS
        action = self.events.get(info.k + 1)
        if action is not None:
            action()

    def run(self, n, jaw=0.4, events=None):
        self.events = events or {}
        loop = FrameLoop(self.character.shape_names, self.renderer, RecordedClock(), fps=FPS, log=lambda s: None,
                         stages=[self.pipeline], observers=[self._hook], overlays=(self.panel.overlay,))
        loop.run(ReplaySource(_frames(jaw, n)), duration=(n - 1) / FPS)
        return self.renderer.read_pixels()

    def click(self, label, n=8):
        x0, y0, x1, y1 = self.panel.rects[label]
        x, y = (x0 + x1) / 2, (y0 + y1) / 2
        io = self.panel.io
        self.run(n, events={2: lambda: (io.add_mouse_pos_event(x, y), io.add_mouse_button_event(0, True)),
                            4: lambda: io.add_mouse_button_event(0, False)})

    def close(self):
        self.panel.close()
        self.renderer.close()


@pytest.fixture
def run(egl_ctx):
    r = _Run(egl_ctx)
    yield r
    r.close()


def _bar_length(image, rect, colour):
    """Pixels of ``colour`` along the middle row of a meter's rectangle."""
    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    row = image[(y0 + y1) // 2, x0:x1, :3].astype(int)
    want = np.round(np.array(colour[:3]) * 255).astype(int)
    return int((np.abs(row - want).max(axis=1) <= 3).sum()), x1 - x0


def test_the_meter_bars_are_as_long_as_the_values(egl_ctx):
    lengths = {}
    for jaw in (0.25, 0.75):
        r = _Run(egl_ctx)
        try:
            image = r.run(40, jaw=jaw)  # settled: the filter's output is the constant input
            for j in range(3):  # raw, filtered, mapped meters of jawOpen (the first row)
                lengths[jaw, j] = _bar_length(image, r.panel.rects[f"meter.0.{j}"], METER_COLOURS[j])
        finally:
            r.close()
    for j in range(3):
        (short, width), (long, _) = lengths[0.25, j], lengths[0.75, j]
        assert abs(short - 0.25 * width) <= 2, (j, short, width)
        assert abs(long - 0.75 * width) <= 2, (j, long, width)  # no value text over the bar
        assert 2.6 < long / short < 3.4


def test_a_bar_ends_on_a_whole_pixel_without_a_blended_edge(run):
    """0.37 of an 80 px meter is 29.6 px: drawn as 30 whole pixels of the bar's colour (a fractional corner would
    make ImGui anti-alias the edge: a blended pixel, and five times the triangles)."""
    image = run.run(40, jaw=0.37)
    x0, y0, x1, y1 = (int(round(v)) for v in run.panel.rects["meter.0.0"])
    row = image[(y0 + y1) // 2, x0:x1, :3].astype(int)
    want = np.round(np.array(METER_COLOURS[0][:3]) * 255).astype(int)
    off = np.abs(row - want).max(axis=1)
    assert (off[:30] <= 3).all() and (off[30:] > 40).all(), off[25:35]


def test_a_settings_section_out_of_view_is_not_built_and_comes_back_clickable_when_scrolled_to(run):
    run.run(6)
    rects = run.panel.rects
    assert "filter.mouth.beta" in rects  # in view
    assert "header.chain" not in rects  # the last section is below the window's bottom: not built, nothing to click
    io = run.panel.io
    x, y = rects["filter.mouth.beta"][0] + 5, rects["filter.mouth.beta"][1] + 5  # over the window, not the list

    def wheel(amount):
        return lambda: (io.add_mouse_pos_event(x, y), io.add_mouse_wheel_event(0.0, amount))
    run.run(6, events={2: wheel(-30.0)})  # down, as far as it goes
    rects = run.panel.rects
    # the blank items stood in for the unbuilt sections with their heights: the scroll reaches the last one
    assert "header.chain" in rects and rects["header.chain"][3] < H
    assert "character.text" not in rects  # "Chain, character" starts closed
    run.click("header.chain")
    run.run(6, events={2: wheel(-30.0)})  # the open section is taller: down to its end
    assert "character.text" in run.panel.rects and run.panel.rects["character.text"][3] < H
    run.run(6, events={2: wheel(30.0)})  # back to the top
    assert "header.chain" not in run.panel.rects and "character.text" not in run.panel.rects
    assert run.panel.rects["filter.mouth.beta"][1] == pytest.approx(y - 5)  # where it was


def test_the_selected_channel_shows_this_frames_values(run):
    run.run(6, jaw=0.3)
    assert "response.values" not in run.panel.rects  # nothing selected yet
    run.click("channel.jawOpen")
    assert run.panel.selected == "jawOpen"
    run.run(20, jaw=0.6)
    raw, filtered, mapped = run.panel._selected_values("jawOpen")
    assert raw == pytest.approx(0.6)
    assert filtered == pytest.approx(0.6, abs=0.01) and mapped == pytest.approx(filtered)
    assert run.panel.rects["response.values"][1] >= run.panel.rects["response.name"][3]  # the line under the name
