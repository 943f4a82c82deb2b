"""The panel's "mapped" meter on a character driven through VRM expressions (real EGL context, renderer,
expression drive and frame loop): a channel the map sends to an expression shows that expression's value,
one sent to a shape that shape's weight, one sent nowhere nothing (before, every channel of a VRM avatar
driven through its presets showed nothing there)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.live.stages import Chain
from facepuppet.runtime.mapping.expressions import ExpressionMap, make_drive
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.gltf_characters import parts_character

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

from facepuppet.runtime.panel.desk import DeskPanel  # noqa: E402

CHANNELS = ("eyeBlinkLeft", "jawOpen", "A", "nothingAtAll")


def _drive(egl_ctx, c, channels, values, n):
    """A panel over ``c`` driven through its expressions by ``n`` frames of ``values`` in a real frame loop:
    (panel, the last tick's info)."""
    drive = make_drive(c.shape_names, c.expressions)
    renderer = FaceRenderer(egl_ctx, c, 320, 240, path="gpu", log=lambda s: None)
    chain = Chain(input="test", stages=(), names=c.shape_names, mapper=Mapper(c.shape_names, drive))
    seen = []
    panel = DeskPanel(egl_ctx, renderer.fbo, 320, 240, chain=chain, character=c, input_kind="test",
                      address="127.0.0.1:1", clock=lambda: len(seen) / 30)
    frames = [Frame(t=i / 30, source="test", channels=channels, weights=np.array(values)) for i in range(n)]
    loop = FrameLoop(c.shape_names, renderer, RecordedClock(), fps=30.0, log=lambda s: None, mapper=chain.mapper,
                     observers=[lambda info: seen.append(info)], overlays=(panel.overlay,))
    loop.run(ReplaySource(frames), duration=(n - 1) / 30)
    renderer.close()
    return panel, seen[-1]


def test_first_targets_name_the_shape_or_expression_each_channel_drives():
    c = parts_character()
    drive = make_drive(c.shape_names, c.expressions)
    first = ExpressionMap(drive, CHANNELS).first_targets()
    n_s = len(c.shape_names)
    names = c.expressions.names
    assert first[1] == c.shape_names.index("jawOpen")  # an ARKit-named morph, straight
    assert first[2] == n_s + names.index("A")  # a preset expression by its name
    assert first[0] == n_s + names.index("Blink")  # the default ARKit -> VRM preset mapping (no Blink_L here)
    assert first[3] == -1


@pytest.mark.gl
def test_the_mapped_meter_shows_the_expression_a_channel_drives(egl_ctx):
    c = parts_character()
    panel, last = _drive(egl_ctx, c, CHANNELS, [0.7, 0.4, 0.9, 0.5], 8)
    names = c.expressions.names
    expressions = last.expressions
    assert expressions is not None and expressions[names.index("Blink")] == pytest.approx(0.35)  # half of a side
    raw, _, mapped = panel._selected_values("eyeBlinkLeft")
    assert raw == pytest.approx(0.7) and mapped == pytest.approx(float(expressions[names.index("Blink")]))
    assert expressions[names.index("A")] == 1.0  # binary: 0.9 -> 1
    assert panel._selected_values("A")[2] == 1.0
    assert panel._selected_values("jawOpen")[2] == pytest.approx(
        float(last.weights[c.shape_names.index("jawOpen")]))
    assert math.isnan(panel._selected_values("nothingAtAll")[2])


@pytest.mark.gl
def test_a_drop_counted_by_the_receiver_and_the_loop_is_shown_once(egl_ctx):
    c = parts_character()
    fbo = egl_ctx.simple_framebuffer((320, 240))
    counters = {"udp": {"packets": 10, "stale_dropped": 5, "malformed": 2}, "loop": {"stale_dropped": 5}}
    panel = DeskPanel(egl_ctx, fbo, 320, 240, character=c, names=c.shape_names, input_kind="test",
                      address="127.0.0.1:1", clock=lambda: 1.0, counters=lambda: counters)
    panel._refresh(1.0)
    assert panel._status["drops"] == {"stale_dropped": 5, "malformed": 2}


@pytest.mark.gl
@pytest.mark.data
def test_the_mapped_meter_of_a_blink_is_the_eyes_closing_on_godette(egl_ctx):
    """Godette has Blink, Blink_L and Blink_R (binary): what both eyes share goes to Blink, the rest to each
    eye's own; an eye's meter shows the sum, at most 1 (the right eye's own Blink_R alone would read 0 here)."""
    from facepuppet.offline.io.gltf.read import read_gltf
    from tests.conftest import need_shared

    c = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    panel, last = _drive(egl_ctx, c, ("eyeBlinkLeft", "eyeBlinkRight"), [0.9, 0.2], 6)
    ex, names = last.expressions, c.expressions.names
    assert ex[names.index("Blink")] == pytest.approx(0.2)  # shared
    assert ex[names.index("Blink_L")] == 1.0 and ex[names.index("Blink_R")] == 0.0  # 0.7 and 0: binary
    assert panel._selected_values("eyeBlinkLeft")[2] == pytest.approx(1.0)
    assert panel._selected_values("eyeBlinkRight")[2] == pytest.approx(0.2)
