"""The panel's config editors driven headless (EGL, the real pipeline, clicks and keys through ImGui's IO):
per-channel response, blink linking and mirror, tracking loss per region, profile Save / Save as / Revert."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import load_live_config
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.mapper import Mapper, follow_mapping
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.profiles import Profile, config_to_toml, parse_config_text, read_made_for
from facepuppet.runtime.live.stages import Chain
from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.small_characters import sphere_character

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

from facepuppet.runtime.panel.desk import DeskPanel  # noqa: E402

pytestmark = pytest.mark.gl
W, H, FPS = 480, 1400, 30.0  # tall: every section is on screen, none scrolled away
CHANNELS = ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight")
YAW = 0.3  # rad, the head's yaw in the frames


def _frames(n, weights=(0.4, 0.2, 0.7)):
    rot = np.array([0.0, math.sin(YAW / 2), 0.0, math.cos(YAW / 2)])
    return [Frame(t=i / FPS, source="test", channels=CHANNELS, weights=np.array(weights), head_rotation=rot)
            for i in range(n)]


class _Run:
    """The sphere head, a LivePipeline (with a chain, and a profile when given) and a DeskPanel in a FrameLoop on
    recorded time; each tick's panel edits, rig weights and frame after the stages are kept in ``ticks``."""

    def __init__(self, ctx, config=None, profile=None):
        self.character = sphere_character()
        self.renderer = FaceRenderer(ctx, self.character, W, H, path="gpu", log=lambda s: None)
        self.pipeline = LivePipeline(config, log=lambda s: None)
        self.chain = Chain(input="test", stages=(self.pipeline,), names=self.character.shape_names,
                           filter=self.pipeline, config=config, profile=profile,
                           mapper=Mapper(self.character.shape_names, log=lambda s: None))
        # as the session wires it: a [mapping] applied live maps from then on
        self.pipeline.bus.on_config(follow_mapping(self.chain.mapper, self.character.expressions, lambda s: None))
        self.now = 0.0
        self.panel = DeskPanel(ctx, self.renderer.fbo, W, H, pipeline=self.pipeline, chain=self.chain,
                               character=self.character, input_kind="test", address="127.0.0.1:1",
                               clock=lambda: self.now)
        self.events = {}
        self.ticks = []

    def _hook(self, info):
        self.now += 1.0 / FPS
        frame = info.frame
        self.ticks.append((self.panel.edits, info.weights.copy(), frame.weights.copy(),
                           None if frame.head_rotation is None else frame.head_rotation.copy()))
        action = self.events.get(info.k + 1)
        if action is not None:
            action()

    def run(self, n, events=None):
        self.events = events or {}
        self.ticks = []
        loop = FrameLoop(self.character.shape_names, self.renderer, RecordedClock(), fps=FPS, log=lambda s: None,
                         stages=[self.pipeline], observers=[self._hook], overlays=(self.panel.overlay,),
                         mapper=self.chain.mapper)
        loop.run(ReplaySource(_frames(n)), duration=(n - 1) / FPS)

    def rect(self, label):
        x0, y0, x1, y1 = self.panel.rects[label]
        assert y1 < H, f"{label} is drawn below the frame ({y1} >= {H})"
        return x0, y0, x1, y1

    def click(self, label, along=0.5, n=10):
        """Press at tick 2 and release at tick 4 at ``along`` of the widget's width (a slider: that value)."""
        x0, y0, x1, y1 = self.rect(label)
        x, y = x0 + along * (x1 - x0), (y0 + y1) / 2
        self.run(n, {2: lambda: self._mouse(x, y, True), 4: lambda: self._mouse(x, y, False)})

    def _mouse(self, x, y, down):
        self.panel.io.add_mouse_pos_event(float(x), float(y))
        self.panel.io.add_mouse_button_event(0, down)

    def first_edit(self, before):
        """Index of the first tick whose panel draw handed a config to the pipeline."""
        return next(i for i, t in enumerate(self.ticks) if t[0] > before)

    def close(self):
        self.panel.close()
        self.renderer.close()


def _assert_round_trips(config):
    """What the panel made is a valid config of the ``--config`` schema: written and read back, the same."""
    back = parse_config_text(config_to_toml(config), "<panel>")

    def unplaced(c):  # where a config (and its mapping, for messages) was read from aside
        return replace(c, path="", mapping=replace(c.mapping, path=""))
    assert unplaced(back) == unplaced(config)


@pytest.fixture
def run(egl_ctx):
    r = _Run(egl_ctx)
    yield r
    r.close()


def test_the_drives_menu_maps_the_selected_channel_onto_another_shape_from_the_next_tick(run):
    """jawOpen (0.4 in every frame) drives the sphere's jawOpen by name; picked in the list, the shape puff
    instead (a [mapping.channels] entry), then nothing, then by name again. The list lies in the desk's window,
    above the settings' (a pop-up would open under them)."""
    run.run(6)
    run.click("channel.jawOpen")
    run.run(3)
    assert [t[1].tolist() for t in run.ticks][-1] == pytest.approx([0.4, 0.0])
    assert "response.drives.puff" in run.panel.rects  # the list of what it may drive
    edits = run.panel.edits
    run.click("response.drives.puff")
    k = run.first_edit(edits)
    rig = [t[1].tolist() for t in run.ticks]
    assert rig[k] == pytest.approx([0.4, 0.0])  # the tick the panel handed the config over maps as before
    assert rig[k + 1] == pytest.approx([0.0, 0.4]) and rig[-1] == pytest.approx([0.0, 0.4])
    mapping = run.pipeline.config.mapping
    assert [t.to for t in mapping.channels[canonical("jawOpen")]] == ["puff"]
    _assert_round_trips(run.pipeline.current_config())
    settings_top = min(y0 for label, (_, y0, _, _) in run.panel.rects.items() if label.startswith("filter."))
    assert all(run.rect(f"response.drives.{n}")[3] < settings_top for n in ("(by name)", "(nothing)", "puff"))
    for choice, want in (("(nothing)", [0.0, 0.0]), ("(by name)", [0.4, 0.0])):
        run.click(f"response.drives.{choice}")
        assert [t[1].tolist() for t in run.ticks][-1] == pytest.approx(want), choice
    assert canonical("jawOpen") not in run.pipeline.config.mapping.channels


def test_a_curve_change_changes_the_mapped_value_of_that_channel_at_the_next_tick(run):
    run.run(6)
    run.click("channel.jawOpen")
    assert run.panel.selected == "jawOpen"
    assert run.panel.edits == 0  # selecting is no edit
    run.run(3)  # the editor of jawOpen laid out
    run.click("response.curve.ease")
    k = run.first_edit(0)
    jaw = [t[1][0] for t in run.ticks]  # the rig's jawOpen: what the character gets
    assert jaw[k] == pytest.approx(0.4)  # the tick the panel handed the config over still has the old one
    assert jaw[k + 1] == pytest.approx(0.4 * 0.4 * (3 - 2 * 0.4))  # smoothstep from the next tick on
    assert jaw[-1] == pytest.approx(jaw[k + 1])
    assert [t[2][1] for t in run.ticks] == pytest.approx([0.2] * len(run.ticks))  # the other channels as they were
    assert run.pipeline.config.channel("jawOpen").curve == "ease"

    run.click("response.curve.threshold")
    run.run(3)  # the threshold slider appears with the threshold curve
    edits = run.panel.edits
    run.click("response.threshold", along=0.9)  # 0..1 slider: about 0.9, above jawOpen's 0.4
    settings = run.pipeline.config.channel("jawOpen")
    assert settings.curve == "threshold" and 0.85 < settings.threshold < 0.95
    k = run.first_edit(edits)
    jaw = [t[1][0] for t in run.ticks]
    assert jaw[k] == pytest.approx(0.4)  # threshold 0.1 (the default) at the press: linear above it
    assert jaw[-1] == 0.0  # 0.4 is under the threshold now: the output range's low end
    _assert_round_trips(run.pipeline.current_config())


def test_gain_clamp_and_ranges_reach_the_channel(run):
    run.run(6)
    run.click("channel.jawOpen")
    run.run(3)
    run.click("response.gain", along=0.9)  # 0..3: gain about 2.7
    gain = run.pipeline.config.channel("jawOpen").gain
    assert 2.5 < gain < 2.9
    assert run.ticks[-1][1][0] == pytest.approx(1.0)  # 0.4 * 2.7 clamped to the default clamp high 1.0
    run.click("response.clamp_high", along=0.5)  # -1..2: clamp high 0.5
    lo, hi = run.pipeline.config.channel("jawOpen").clamp
    assert lo == 0.0 and 0.45 < hi < 0.55
    assert run.ticks[-1][1][0] == pytest.approx(hi)
    run.click("response.in_high", along=0.995)  # input range [0, 2]: v = 0.4 * gain maps to half of it
    run.click("response.out_to", along=0.005)  # output range [0, -1]: an inverted channel ...
    cs = run.pipeline.config.channel("jawOpen")
    assert cs.input_range == pytest.approx((0.0, 2.0), abs=0.03)
    assert cs.output_range == pytest.approx((0.0, -1.0), abs=0.03)
    u = 0.4 * cs.gain / 2.0
    assert run.ticks[-1][1][0] == pytest.approx(max(-u, 0.0))  # ... clamped at 0 below
    assert run.ticks[-1][2][0] == pytest.approx(0.0)
    _assert_round_trips(run.pipeline.current_config())
    run.click("response.reset")
    assert "jawopen" not in {k.lower() for k in run.pipeline.config.channels}
    assert run.ticks[-1][1][0] == pytest.approx(0.4)


def test_mirror_swaps_the_sides_and_link_blinks_takes_the_stronger(run):
    run.run(6)
    assert list(run.ticks[-1][2]) == pytest.approx([0.4, 0.2, 0.7])
    run.click("face.mirror")
    k = run.first_edit(0)
    assert list(run.ticks[k][2]) == pytest.approx([0.4, 0.2, 0.7])
    assert list(run.ticks[k + 1][2]) == pytest.approx([0.4, 0.7, 0.2])  # left <- right, at the next tick
    rot = run.ticks[-1][3]
    assert rot[1] == pytest.approx(-math.sin(YAW / 2), abs=1e-6)  # the yaw negated
    assert run.pipeline.config.mirror
    run.click("face.link_blinks")
    assert run.pipeline.config.link_blinks
    assert list(run.ticks[-1][2]) == pytest.approx([0.4, 0.7, 0.7])
    run.click("face.mirror")
    assert not run.pipeline.config.mirror
    assert list(run.ticks[-1][2]) == pytest.approx([0.4, 0.7, 0.7])  # linked still
    _assert_round_trips(run.pipeline.current_config())


def test_the_tracking_loss_mode_of_a_region_is_selectable(run):
    run.run(6)
    assert "loss.eyes.voice" not in run.panel.rects  # voice drives the mouth only
    assert "loss.mouth.voice" in run.panel.rects
    run.click("loss.eyes.idle")
    run.click("loss.mouth.voice")
    run.click("loss.head.hold")
    modes = run.pipeline.config.loss.modes
    assert (modes["eyes"], modes["mouth"], modes["head"], modes["brows"]) == ("idle", "voice", "hold", "neutral")
    _assert_round_trips(run.pipeline.current_config())


def _write_profile(path, gain):
    path.write_text('[profile]\ncharacter = "other.npz"\ninput = "vmc"\n\n'
                    f'[channels.jawOpen]\ngain = {gain}\n', encoding="utf-8")


def test_profile_save_writes_the_file_and_revert_restores_it(egl_ctx, tmp_path):
    path = tmp_path / "show.toml"
    _write_profile(path, 0.5)
    profile = Profile(path, character="sphere", input_kind="test", log=lambda s: None)
    run = _Run(egl_ctx, config=profile.load(), profile=profile)
    try:
        run.run(6)
        assert "other.npz" in run.panel.profile_warning and "'vmc'" in run.panel.profile_warning
        assert "profile.warning" in run.panel.rects  # shown
        assert run.ticks[-1][1][0] == pytest.approx(0.2)  # jawOpen 0.4 at the profile's gain 0.5
        run.click("channel.jawOpen")
        run.run(3)
        run.click("response.gain", along=0.5)  # gain about 1.5
        gain = run.pipeline.config.channel("jawOpen").gain
        assert 1.4 < gain < 1.6
        run.click("calibrate", n=30)  # a neutral captured (0.5 s of frames) is saved with the rest
        assert run.pipeline.counters["calibrations"] == 1
        run.click("profile.save")
        saved = load_live_config(path)
        assert saved.channel("jawOpen").gain == pytest.approx(gain)
        assert dict(zip(saved.neutral.channels, saved.neutral.weights)) == pytest.approx(
            dict(zip(CHANNELS, (0.4, 0.2, 0.7))))
        assert read_made_for(path)["character"] == "sphere"
        assert run.panel.profile_warning == ""  # made for this run now

        run.click("face.mirror")
        run.click("response.gain", along=0.1)
        assert run.pipeline.config.mirror and run.pipeline.config.channel("jawOpen").gain < 0.5
        run.click("clear")
        assert run.pipeline.neutral_weights is None
        run.click("profile.revert")
        config = run.pipeline.current_config()
        assert config.neutral == saved.neutral  # the saved neutral is back
        assert not config.mirror and config.channel("jawOpen").gain == pytest.approx(gain)
        assert run.ticks[-1][1][0] == pytest.approx(0.0, abs=1e-6)  # jawOpen at its neutral

        other = tmp_path / "second.toml"
        run.click("profile.name")
        run.run(4, {2: lambda: run.panel.io.add_input_characters_utf8(str(other))})
        assert run.panel.profile_name == str(other)
        run.click("profile.save_as")
        assert other.exists() and profile.path == other
        assert load_live_config(other).channel("jawOpen").gain == pytest.approx(gain)
        assert str(other) in run.panel.profile_message
    finally:
        run.close()


def test_a_profile_action_that_fails_says_why_and_keeps_the_config(egl_ctx, tmp_path):
    path = tmp_path / "show.toml"
    _write_profile(path, 0.5)
    profile = Profile(path, character="sphere", input_kind="test", log=lambda s: None)
    run = _Run(egl_ctx, config=profile.load(), profile=profile)
    try:
        run.run(4)
        before = run.pipeline.current_config()
        run.click("profile.save_as")  # no name typed
        assert "type a profile name" in run.panel.profile_message
        path.write_text("[channels.jawOpen]\ngain = 'loud'\n", encoding="utf-8")  # broken under the run
        run.click("profile.revert")
        assert "revert: failed" in run.panel.profile_message and "gain" in run.panel.profile_message
        assert run.pipeline.current_config() == before
    finally:
        run.close()
