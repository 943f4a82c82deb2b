"""The settings' window in its own ImGui context, built only when what it shows changes, driven headless (real
EGL context, renderer and pipeline, events through the panel's IO, which hands them to both contexts); and the
channel rows as one item (a click selects the row under the mouse)."""

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

from facepuppet.runtime.panel.desk import PANEL_WIDTH, DeskPanel  # noqa: E402
from facepuppet.runtime.panel.retained import SETTLE_FRAMES  # noqa: E402

pytestmark = pytest.mark.gl
FPS = 30.0
CHANNELS = ("jawOpen", "eyeBlinkLeft", "puff", "browInnerUp", "mouthSmileLeft")


def _frames(n, jaw=0.4):
    """``n`` frames; ``jaw`` a number, or a callable of the frame's index."""
    value = jaw if callable(jaw) else (lambda i: jaw)
    return [Frame(t=i / FPS, source="test", channels=CHANNELS, weights=np.array([value(i), 0.2, 0.5, 0.1, 0.3]))
            for i in range(n)]


class _Run:
    def __init__(self, ctx, width, height):
        self.character = sphere_character()
        self.renderer = FaceRenderer(ctx, self.character, width, height, path="gpu", log=lambda s: None)
        self.pipeline = LivePipeline(log=lambda s: None)
        self.now = 0.0
        self.panel = DeskPanel(ctx, self.renderer.fbo, width, height, pipeline=self.pipeline,
                               character=self.character, names=self.character.shape_names, input_kind="test",
                               address="127.0.0.1:1", clock=lambda: self.now)
        self.events = {}

    def _hook(self, info):
        self.now += 1.0 / FPS
        action = self.events.get(info.k + 1)
        if action is not None:
            action()

    def run(self, n, events=None, jaw=0.4):
        self.events = events or {}
        loop = FrameLoop(self.character.shape_names, self.renderer, RecordedClock(), fps=FPS, log=lambda s: None,
                         stages=[self.pipeline], observers=[self._hook], overlays=(self.panel.overlay,))
        loop.run(ReplaySource(_frames(n, jaw)), duration=(n - 1) / FPS)
        return self.renderer.read_pixels()

    def press(self, label, n=10):
        x0, y0, x1, y1 = self.panel.rects[label]
        x, y = (x0 + x1) / 2, (y0 + y1) / 2
        io = self.panel.io
        return self.run(n, events={2: lambda: (io.add_mouse_pos_event(x, y), io.add_mouse_button_event(0, True)),
                                   4: lambda: io.add_mouse_button_event(0, False),
                                   6: lambda: io.add_mouse_pos_event(-100.0, -100.0)})  # the mouse leaves

    def close(self):
        self.panel.close()
        self.renderer.close()


@pytest.fixture(params=[(1280, 720), (480, 640)], ids=["wide", "narrow"])
def run(request, egl_ctx):
    r = _Run(egl_ctx, *request.param)
    yield r
    r.close()


def test_the_settings_are_built_again_only_when_something_on_them_changes(run):
    run.run(12)
    settled = run.panel.settings_builds
    assert settled <= 2 * SETTLE_FRAMES + 1  # the first frames (and the desk's foot settling), not one per tick
    assert run.panel.live_builds == 12  # the live layer (meters, status lines): every tick
    desk = run.panel.desk_builds
    assert desk <= 2 * SETTLE_FRAMES + 1
    run.run(20)
    assert run.panel.settings_builds == settled  # nothing changed: the last frame drawn again, 20 times
    assert run.panel.desk_builds == desk
    before = run.renderer.read_pixels()
    image = run.press("calibrate", n=10)  # "no neutral" -> "capturing...": an event and a change of what it shows
    assert run.panel.settings_builds > settled
    assert run.pipeline.calibrating or run.pipeline.counters["calibrations"] == 1
    x0, y0, x1, y1 = (int(v) for v in run.panel.rects["clear"])
    line = (slice(y0, y1), slice(x1, min(x1 + 250, image.shape[1])))  # the calibration text right of Clear
    assert (image[line] != before[line]).any()  # the settings' pixels show the new state
    capturing = run.panel.settings_builds
    later = run.run(40)  # the capture completes (0.5 s): a change on the settings without any event
    assert run.pipeline.counters["calibrations"] == 1
    done = run.panel.settings_builds
    assert done > capturing and (later[line] != image[line]).any()  # "neutral set (1 calibrations)" drawn
    run.run(20)
    assert run.panel.settings_builds == done


def test_a_filter_slider_in_the_settings_window_reaches_the_pipeline(run):
    run.run(6)
    x0, y0, x1, y1 = run.panel.rects["filter.mouth.beta"]
    x, y = x0 + 0.9 * (x1 - x0), (y0 + y1) / 2
    io = run.panel.io
    run.run(10, events={2: lambda: (io.add_mouse_pos_event(x, y), io.add_mouse_button_event(0, True)),
                        5: lambda: io.add_mouse_button_event(0, False)})
    assert 4.0 < run.pipeline.config.filters["mouth"].beta < 5.0
    assert run.panel.selected is None  # the desk's context saw the click on empty space: nothing selected


def test_the_settings_window_sits_beside_or_under_the_desk(run):
    run.run(8)
    w, h = run.panel.window_size
    fx0, fy0, _, _ = run.panel.rects["filter.mouth.min_cutoff"]
    _, _, _, desk_foot = run.panel.rects["channel.mouthSmileLeft"]
    if w >= 2 * PANEL_WIDTH + 200:
        assert fx0 > w - PANEL_WIDTH - 8  # at the right edge
    else:
        assert fx0 < PANEL_WIDTH and fy0 > desk_foot  # under the desk's window, the channels in view above it


def test_a_click_on_a_channel_row_selects_that_row(run):
    run.run(6)
    run.press("channel.puff")
    assert run.panel.selected == "puff"
    run.press("channel.browInnerUp")
    assert run.panel.selected == "browInnerUp"
    raw, filtered, _ = run.panel._selected_values("browInnerUp")
    assert raw == pytest.approx(0.1) and filtered == pytest.approx(0.1, abs=0.02)


def _bar(image, rect):
    """Pixels of the raw meter's colour along the middle row of the meter ``rect``."""
    from facepuppet.runtime.panel.channels import METER_COLOURS

    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    row = image[(y0 + y1) // 2, x0:x1, :3].astype(int)
    want = np.round(np.array(METER_COLOURS[0][:3]) * 255).astype(int)
    return int((np.abs(row - want).max(axis=1) <= 3).sum())


def test_the_meters_follow_the_values_while_the_desk_window_is_not_built_again(run):
    run.run(12, jaw=0.2)
    desk, rect = run.panel.desk_builds, run.panel.rects["meter.0.0"]
    low = _bar(run.renderer.read_pixels(), rect)
    high = _bar(run.run(12, jaw=0.9), rect)
    assert run.panel.desk_builds == desk  # the same channels, rows and layout: its last frame drawn again
    assert high > 3 * low > 0  # the live layer drew this tick's bar (jawOpen's raw meter: the first row)
    ramp = run.run(30, jaw=lambda i: 0.9 if i < 15 else 0.2)
    assert _bar(ramp, rect) == pytest.approx(low, abs=2)
    assert run.panel.desk_builds == desk
