"""Profiles: where they live, save -> load round trip (neutral included), made-for warnings, bad files refused."""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

from facepuppet.runtime.live.config import ChannelSettings, FilterSettings, LiveConfig, LiveConfigError, Neutral
from facepuppet.runtime.live.profiles import Profile, config_to_toml, parse_config_text, profile_path, profiles_dir
from facepuppet.runtime.mapping.expressions import MappingSettings, MappingTarget


def tuned() -> LiveConfig:
    """A config with every kind of setting away from its default."""
    filters = {**LiveConfig().filters, "mouth": FilterSettings(0.8, 0.25, 1.5), "head": FilterSettings(2.0, 0.0)}
    return LiveConfig(
        filters=filters,
        channels={"jawOpen": ChannelSettings(1.3, (0.0, 0.9), (0.05, 0.8), (0.0, 1.0), "threshold", 0.07),
                  "eyeBlinkLeft": ChannelSettings(curve="ease", output_range=(1.0, 0.1)),
                  "mouthSmileRight": ChannelSettings(gain=0.1 + 0.2)},  # 0.30000000000000004 survives
        default_channel=ChannelSettings(gain=1.1, clamp=(-0.5, 1.0)),
        timeout_s=0.3, ease_out_s=1.25, ease_in_s=0.125, capture_s=0.75, link_blinks=True, mirror=True,
        neutral=Neutral(("jawOpen", "eyeBlinkLeft", "brow \"odd\" name"), (0.0612345678901234, 0.1, -1e-9),
                        (0.01, -0.02, 0.003, 0.99975), (0.1, 0.2, -0.3)),
        mapping=MappingSettings(True, {"jawOpen": (MappingTarget("A", 1.2), MappingTarget("ah")), "tongueOut": ()},
                                {"jawOpen": "JawOpen", "tongueOut": "tongueOut"}),
    )


def same(a: LiveConfig, b: LiveConfig) -> bool:
    """Equal settings, whatever file each names."""
    return replace(a, path="", mapping=replace(a.mapping, path="")) == \
        replace(b, path="", mapping=replace(b.mapping, path=""))


def test_a_name_lives_under_xdg_config_home_and_a_path_is_a_path(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert profiles_dir() == tmp_path / "xdg" / "facepuppet" / "profiles"
    assert profile_path("show-1") == tmp_path / "xdg" / "facepuppet" / "profiles" / "show-1.toml"
    assert profile_path(str(tmp_path / "mine.toml")) == tmp_path / "mine.toml"
    assert profile_path("rehearsal.toml") == Path("rehearsal.toml")  # a .toml name is a path, here
    monkeypatch.delenv("XDG_CONFIG_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert profile_path("show") == tmp_path / "home" / ".config" / "facepuppet" / "profiles" / "show.toml"
    for bad in ("", " show", ".hidden", "a b"):
        with pytest.raises(ValueError, match="--profile"):
            profile_path(bad)


def test_save_then_load_gives_the_identical_config_neutral_included(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    cfg = tuned()
    logs = []
    saved = Profile(profile_path("show"), character="ict.npz", input_kind="livelinkface", log=logs.append).save(cfg)
    assert saved == tmp_path / "facepuppet" / "profiles" / "show.toml"  # its folder was made
    back = Profile(saved, character="ict.npz", input_kind="livelinkface", log=logs.append).load()
    assert same(back, cfg)
    assert back.neutral == cfg.neutral and back.neutral.weights[0] == 0.0612345678901234
    assert back.channel("mouthSmileRight").gain == 0.1 + 0.2
    assert not any("warning" in line for line in logs)
    made = tomllib.loads(saved.read_text())["profile"]
    assert made["character"] == "ict.npz" and made["input"] == "livelinkface" and made["saved"]
    # a profile is a config file: --config reads it too, and its text round-trips as well
    assert same(parse_config_text(config_to_toml(cfg), "x"), cfg)
    assert not list(saved.parent.glob("*.tmp*")) and [p.name for p in saved.parent.iterdir()] == ["show.toml"]


def test_a_profile_made_for_another_character_warns_naming_both(tmp_path):
    path = tmp_path / "p.toml"
    Profile(path, character="godette.vrm", input_kind="vmc", log=lambda s: None).save(tuned())
    logs = []
    config = Profile(path, character="ict.npz", input_kind="vmc", log=logs.append).load()
    warnings = [line for line in logs if "warning" in line]
    assert len(warnings) == 1
    assert "made for character 'godette.vrm'" in warnings[0] and "'ict.npz'" in warnings[0]
    assert str(path) in warnings[0]
    assert same(config, tuned())  # it still applies
    logs.clear()
    Profile(path, character="godette.vrm", input_kind="livelinkface", log=logs.append).load()
    assert any("made for input 'vmc'" in line and "'livelinkface'" in line for line in logs)


def test_save_as_moves_the_profile_and_revert_gives_back_what_was_saved(tmp_path):
    first = tmp_path / "a.toml"
    profile = Profile(first, log=lambda s: None)
    assert same(profile.load(), LiveConfig()) and not profile.exists  # new: defaults until the first Save
    profile.save(tuned())
    edited = replace(tuned(), link_blinks=False)
    assert same(profile.revert(), tuned())
    second = profile.save_as(str(tmp_path / "b.toml"), edited)
    assert profile.path == second and same(Profile(second, log=lambda s: None).load(), edited)
    assert same(Profile(first, log=lambda s: None).load(), tuned())  # the old file is left as it was


def test_a_failed_save_leaves_the_old_profile_whole(tmp_path):
    path = tmp_path / "p.toml"
    profile = Profile(path, log=lambda s: None)
    profile.save(tuned())
    before = path.read_bytes()
    with pytest.raises(ValueError, match="finite"):
        profile.save(replace(tuned(), channels={"jawOpen": ChannelSettings(gain=math.nan)}))
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["p.toml"]


@pytest.mark.parametrize("text, match", [
    ('[channels.jawOpen]\ncurve = "cubic"', r"key 'channels.jawOpen.curve': expected one of linear, ease, threshold"),
    ("[channels.jawOpen]\ninput_range = [0.5, 0.5]", r"key 'channels.jawOpen.input_range': expected low < high"),
    ("[channels.jawOpen]\noutput_range = [0.5]", r"key 'channels.jawOpen.output_range': expected an array of two"),
    ('[channels.jawOpen]\nthreshold = "low"', r"key 'channels.jawOpen.threshold': expected a finite number"),
    ("[channels.jawOpen]\nshape = 1", r"key 'channels.jawOpen.shape': unknown key"),
    ("[face]\nmirror = 1", r"key 'face.mirror': expected true or false, got 1"),
    ("[face]\nlink_blink = true", r"key 'face.link_blink': unknown key; expected one of link_blinks, mirror"),
    ('[neutral]\nchannels = ["jawOpen"]\nweights = [0.1, 0.2]', r"key 'neutral.weights': expected 1 numbers"),
    ('[neutral]\nchannels = ["jawOpen"]\nweights = [0.1]\nrotation = [0, 0, 0, 0]',
     r"key 'neutral.rotation': expected a unit quaternion"),
    ('[neutral]\nchannels = ["jawOpen"]\nweights = [0.1]\ntranslation = [0, 0]',
     r"key 'neutral.translation': expected an array of 3 numbers"),
    ("[neutral]\nchannels = [1]\nweights = [0.1]", r"key 'neutral.channels': expected an array of channel names"),
    ("[profile]\ncharacter = 3", r"key 'profile.character': expected a string, got 3"),
    ("[profile]\nmade = 'x'", r"key 'profile.made': unknown key"),
])
def test_bad_profile_values_are_refused_naming_the_file_and_key(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(LiveConfigError, match=match) as info:
        Profile(path, log=lambda s: None).load()
    assert str(path) in str(info.value)


def test_run_refuses_config_and_profile_together(tmp_path):
    from facepuppet.runtime.cli import main

    from helpers.small_characters import sphere_character

    char = sphere_character().save(tmp_path / "s.npz")
    (tmp_path / "c.toml").write_text("")
    code = main(["run", "-c", str(char), "--input", "vmc", "--listen", "127.0.0.1:0", "--headless",
                 "--duration", "0.1", "--config", str(tmp_path / "c.toml"), "--profile", str(tmp_path / "p.toml")])
    assert code == 2


def test_a_profile_keeps_the_tracking_loss_modes_and_the_mix_orders(tmp_path):
    from facepuppet.runtime.live.mix import MixSettings
    from facepuppet.runtime.live.tracking_loss import LossSettings

    loss = LossSettings({**LossSettings().modes, "mouth": "voice", "eyes": "idle", "head": "hold"},
                        voice_floor_db=-45.0, voice_ceiling_db=-12.5, idle_blink_s=3.0, idle_seed=7)
    mix = MixSettings(order=("livelinkface", "vmc#2", "audio"), regions={"head": ("vmc#2", "livelinkface")},
                      channels={"jawOpen": ("audio", "livelinkface")}, ease_s=0.4)
    cfg = replace(tuned(), loss=loss, mix=mix)
    saved = Profile(tmp_path / "show.toml", character="ict.npz", input_kind="livelinkface").save(cfg)
    back = Profile(saved, character="ict.npz", input_kind="livelinkface").load()
    assert back.loss == loss and back.loss.mode("mouth") == "voice"
    assert back.mix == mix and back.mix.order == ("livelinkface", "vmc#2", "audio")
    assert same(back, cfg)
    # a config without a mix writes no [mix] table (a one-input profile stays as it was)
    assert "[mix]" not in config_to_toml(tuned()) and "[mix]" in config_to_toml(cfg)
