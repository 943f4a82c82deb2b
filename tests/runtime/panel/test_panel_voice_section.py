"""The panel's Voice section: Re-calibrate takes the live voice as silence and each vowel, then Save writes the new
profile over the --voice file (a run's own panel, the WAV on recorded time)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.stages import Chain
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.render.renderer import FaceRenderer
from facepuppet.runtime.voice.source import WavVoice
from facepuppet.runtime.voice.stage import VoiceStage
from facepuppet.runtime.voice.vowels import VOWELS, VowelProfile, build_profile

from helpers.small_characters import sphere_character
from helpers.voice_tables import write_wav

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

from facepuppet.runtime.panel.desk import DeskPanel  # noqa: E402

pytestmark = pytest.mark.gl
W, H, FPS, RATE = 480, 1400, 30.0, 16000


def tone(hz, seconds):
    t = np.arange(int(seconds * RATE)) / RATE
    return 0.3 * np.sin(2 * np.pi * hz * t) * (1 + 0.3 * np.sin(2 * np.pi * 3 * hz * t))


def test_recalibrate_then_save_writes_a_profile_made_from_the_live_voice(egl_ctx, tmp_path):
    old, _ = build_profile({v: tone(300 + 500 * i, 1.0) for i, v in enumerate(VOWELS)}, RATE)
    path = old.save(tmp_path / "me.toml")
    write_wav(tmp_path / "live.wav", np.concatenate([tone(450 + 700 * (i % 5), 0.5) for i in range(12)]))
    character = sphere_character()
    renderer = FaceRenderer(egl_ctx, character, W, H, path="gpu", log=lambda s: None)
    pipeline = LivePipeline(None, log=lambda s: None)
    voice = VoiceStage(WavVoice(tmp_path / "live.wav", VowelProfile.load(path)), path=str(path))
    chain = Chain(input="test", stages=(voice, pipeline), names=character.shape_names, filter=pipeline,
                  mapper=Mapper(character.shape_names, log=lambda s: None), voice=voice)
    now = [0.0]
    panel = DeskPanel(egl_ctx, renderer.fbo, W, H, pipeline=pipeline, chain=chain, character=character,
                      input_kind="test", address="-", clock=lambda: now[0])
    panel._voice.seconds = 0.1  # six takes in 0.6 s of the WAV
    events = {}

    def hook(info):
        now[0] += 1.0 / FPS
        action = events.get(info.k + 1)
        if action is not None:
            action()

    def run(n, t0):
        frames = [Frame(t=t0 + i / FPS, source="test", channels=("jawOpen",), weights=np.array([0.1]))
                  for i in range(n)]
        loop = FrameLoop(character.shape_names, renderer, RecordedClock(), fps=FPS, log=lambda s: None,
                         stages=[voice, pipeline], overlays=(panel.overlay,), mapper=chain.mapper,
                         observers=[hook])
        loop.run(ReplaySource(frames), duration=(n - 1) / FPS)

    def click(label, t0, n=10):
        x0, y0, x1, y1 = panel.rects[label]
        x, y = (x0 + x1) / 2, (y0 + y1) / 2

        def mouse(down):
            panel.io.add_mouse_pos_event(float(x), float(y))
            panel.io.add_mouse_button_event(0, down)
        events.clear()
        events.update({2: lambda: mouse(True), 4: lambda: mouse(False)})
        run(n, t0)
        events.clear()

    try:
        run(4, 0.0)
        assert "voice.recalibrate" in panel.rects and "voice.save" not in panel.rects
        click("voice.recalibrate", 0.2)
        r = panel._voice.recalibration
        assert r is not None and r.phase >= 1  # the takes have begun
        run(30, 0.6)
        assert r.done and r.profile is not None, r.message
        assert voice.source.voice.table is r.profile  # the new profile is in use
        run(3, 1.7)
        click("voice.save", 1.8)
        saved = VowelProfile.load(path)
        np.testing.assert_allclose(saved.templates, r.profile.templates, atol=1e-3)
        assert panel._voice.message == f"saved {path}"
    finally:
        panel.close()
        renderer.close()
