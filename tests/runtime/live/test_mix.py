"""The ``mix`` stage: per-channel source orders, hand-over when a source goes quiet, the voice, the config.

Driven tick by tick on recorded time with scripted sources (the stage's own logic); the run over real UDP
with two inputs is in tests/runtime/commands/test_run_mix.py.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import LiveConfigError, parse_live_config
from facepuppet.runtime.live.mix import MixSettings, MixStage, VoiceMixSource, check_mix_sources, source_names
from facepuppet.runtime.live.tracking_loss import LossSettings

FPS = 60.0
YAW_A = np.array([0.0, math.sin(0.1), 0.0, math.cos(0.1)])
YAW_B = np.array([0.0, math.sin(-0.2), 0.0, math.cos(-0.2)])


class Scripted:
    """A mix source whose frame at tick time t is ``script(t)`` (None: nothing new)."""

    def __init__(self, script):
        self.script = script
        self.counters = {}

    def latest(self, t):
        return self.script(t), 0


def phone(t, jaw=0.6, smile=0.2):
    return Frame(t=t, source="phone", channels=("jawOpen", "mouthSmileLeft"), weights=np.array([jaw, smile],
                 np.float32), head_rotation=YAW_A)


def second(t):
    return Frame(t=t, source="osf", channels=("jawOpen", "eyeBlinkLeft"), weights=np.array([0.3, 0.5], np.float32),
                 head_rotation=YAW_B)


def drive(stage, primary, until):
    out = []
    for k in range(int(until * FPS)):
        t = k / FPS
        out.append((t, stage(primary(t), t)))
    return out


def test_each_channel_from_the_first_live_source_in_its_order_and_the_loss_of_one_hands_over():
    settings = MixSettings(order=("phone", "osf"), regions={"head": ("osf", "phone")}, ease_s=0.2)
    stage = MixStage(("phone", "osf"), {"osf": Scripted(second)}, settings, timeout_s=0.2)
    quiet = (1.0, 2.0)  # the phone sends nothing from 1 s to 2 s
    out = drive(stage, lambda t: None if quiet[0] <= t < quiet[1] else phone(t), 3.0)
    t = np.array([x for x, _ in out])
    frames = [f for _, f in out]
    assert all(f is not None for f in frames)  # osf never stops: every tick has a mixed frame
    assert frames[0].channels == ("jawOpen", "mouthSmileLeft", "eyeBlinkLeft")
    w = np.array([f.weights for f in frames])
    early = t < 1.0
    np.testing.assert_allclose(w[early], np.tile([0.6, 0.2, 0.5], (early.sum(), 1)), atol=1e-6)
    rot = np.array([f.head_rotation for f in frames])
    np.testing.assert_allclose(rot[early], np.tile(YAW_B, (early.sum(), 1)), atol=1e-9)  # head: osf first
    # the phone lost: jaw to osf's (crossfaded over ease_s), the smile (osf has none) eases to 0
    handed = (t >= 1.0 + 0.2 + 0.2 + 1e-9) & (t < 2.0)
    np.testing.assert_allclose(w[handed], np.tile([0.3, 0.0, 0.5], (handed.sum(), 1)), atol=1e-6)
    step = np.abs(np.diff(w[:, 0]))
    assert step.max() <= 1.5 * 0.3 / (0.2 * FPS) + 1e-6  # never a jump
    back = t >= 2.0 + 0.2 + 1e-9
    np.testing.assert_allclose(w[back], np.tile([0.6, 0.2, 0.5], (back.sum(), 1)), atol=1e-6)
    c = stage.counters
    assert c["phone.lost"] == 1 and c["phone.found"] == 2 and c["osf.lost"] == 0 and c["osf.served"] > 0
    assert c["handovers"] == 4  # jaw and smile away from the phone and back
    assert stage.chosen["jawOpen"] == "phone" and stage.chosen["head"] == "osf"


def test_a_channel_order_overrides_its_region_and_nan_passes_to_the_next_source():
    settings = MixSettings(order=("phone", "osf"), channels={"jawOpen": ("osf", "phone")}, ease_s=0.2)
    stage = MixStage(("phone", "osf"), {"osf": Scripted(second)}, settings, timeout_s=0.2)
    frame = stage(phone(0.0, smile=math.nan), 0.0)
    # jaw from osf by its own order; the phone's smile is NaN (not sent) and osf has none: 0
    np.testing.assert_allclose(frame.weights, [0.3, 0.0, 0.5], atol=1e-6)


def test_no_live_tracker_emits_nothing_so_the_filter_stage_sees_the_loss():
    loss = LossSettings(voice_floor_db=-40.0, voice_ceiling_db=-10.0)
    voice = VoiceMixSource(lambda t: -25.0, loss)
    stage = MixStage(("phone", "audio"), {"audio": voice}, MixSettings(order=("phone", "audio")), timeout_s=0.2)
    f = stage(phone(0.0, jaw=math.nan), 0.0)
    np.testing.assert_allclose(f.weights[0], 0.5, atol=1e-6)  # the phone's jaw missing: the voice's
    assert stage.chosen["jawOpen"] == "audio"
    outs = [stage(None, k / FPS) for k in range(1, 30)]
    assert outs[-1] is None  # only the voice left: the mix is quiet, the filter's tracking loss takes over
    assert stage.counters["phone.lost"] == 1


def test_source_names_and_config():
    assert source_names(["vmc", "vmc", "audio", "vmc"]) == ("vmc", "vmc#2", "audio", "vmc#3")
    cfg = parse_live_config(tomllib.loads('[mix]\norder = ["livelinkface", "audio"]\nease_s = 0.1\n'
                                          '[mix.regions]\nhead = ["openseeface", "livelinkface"]\n'
                                          '[mix.channels]\nJawOpen = ["audio", "livelinkface"]\n'), "m.toml")
    assert cfg.mix.order == ("livelinkface", "audio") and cfg.mix.ease_s == 0.1
    assert cfg.mix.regions == {"head": ("openseeface", "livelinkface")}
    assert cfg.mix.channels == {"jawOpen": ("audio", "livelinkface")}
    with pytest.raises(ValueError, match=r"\[mix\] names the source 'openseeface', which this run does not have"):
        check_mix_sources(cfg.mix, ("livelinkface", "audio"), "m.toml")


@pytest.mark.parametrize("text, message", [
    ("[mix]\norder = []", "mix.order': expected a non-empty array of source names"),
    ('[mix]\norder = ["a", "a"]', "mix.order': a source is named twice"),
    ("[mix]\nease_s = 0", "mix.ease_s': expected a finite number > 0"),
    ('[mix]\nodrer = ["a"]', "mix.odrer': unknown key"),
    ('[mix.regions]\nlips = ["a"]', "mix.regions.lips': unknown region"),
    ('[mix.channels]\njawOpn = ["a"]', "mix.channels.jawOpn': no channel of that name; did you mean jawOpen"),
])
def test_bad_mix_settings_name_the_file_and_key(text, message):
    with pytest.raises(LiveConfigError, match="m.toml: key '" + message):
        parse_live_config(tomllib.loads(text), "m.toml")


def test_a_config_applied_live_changes_the_mix_orders_through_the_filters_hook():
    from dataclasses import replace

    from facepuppet.runtime.live.config import FilterSettings, LiveConfig
    from facepuppet.runtime.live.mix import follow_config
    from facepuppet.runtime.live.pipeline import LivePipeline

    fast = FilterSettings(min_cutoff=500.0, beta=0.0)
    cfg = LiveConfig(filters={r: fast for r in ("eyes", "brows", "mouth", "other", "head")},
                     mix=MixSettings(order=("phone", "osf"), ease_s=0.2), timeout_s=0.2)
    stage = MixStage(("phone", "osf"), {"osf": Scripted(second)}, cfg.mix, timeout_s=0.2)
    pipeline, logs = LivePipeline(cfg, log=lambda s: None), []
    pipeline.bus.on_config(follow_config(stage, ("phone", "osf"), logs.append))
    jaw = []
    for k in range(int(1.0 * FPS)):
        t = k / FPS
        if k == 30:  # the panel: the jaw from osf first
            pipeline.apply_config(replace(cfg, mix=replace(cfg.mix, channels={"jawOpen": ("osf", "phone")})))
        jaw.append((t, float(pipeline(stage(phone(t), t), t).weights[0])))
    t, w = np.array([x for x, _ in jaw]), np.array([y for _, y in jaw])
    np.testing.assert_allclose(w[t < 0.5], 0.6, atol=1e-3)  # the phone's jaw until the change
    np.testing.assert_allclose(w[t >= 0.5 + 2 / FPS + 0.2 + 1e-9], 0.3, atol=1e-3)  # osf's after the crossfade
    assert np.abs(np.diff(w)).max() <= 1.5 * 0.3 / (0.2 * FPS) + 1e-3  # handed over without a jump
    assert stage.chosen["jawOpen"] == "osf"
    # an order naming a source this run does not have: refused with a warning, the mix keeps its orders
    pipeline.apply_config(replace(cfg, mix=replace(cfg.mix, channels={"jawOpen": ("vmc#2", "phone")})))
    pipeline(stage(phone(1.0), 1.0), 1.0)
    assert any("mix: warning" in line and "'vmc#2'" in line for line in logs)
    assert stage.settings.channels == {"jawOpen": ("osf", "phone")}
