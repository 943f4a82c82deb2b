"""The live TOML config: defaults, a full file, and errors that name the file, the key and the type."""

from __future__ import annotations

import pytest

from facepuppet.runtime.live.config import DEFAULT_FILTERS, LiveConfig, LiveConfigError, load_live_config

FULL = """
[filter.eyes]
min_cutoff = 4.0
beta = 2
[filter.head]
d_cutoff = 2.5
[tracking_loss]
timeout_s = 0.3
ease_out_s = 1.0
ease_in_s = 0.1
[calibration]
capture_s = 0.75
[channels.JawOpen]
gain = 1.5
clamp = [0.0, 0.9]
[channels.eyeBlink_L]
gain = 0.5
"""


def test_defaults_smooth_mouth_more_than_eyes():
    cfg = LiveConfig()
    assert cfg.filters["mouth"].min_cutoff < cfg.filters["eyes"].min_cutoff
    assert cfg.timeout_s > 0 and cfg.capture_s == 0.5
    assert cfg.channel("jawOpen").gain == 1.0 and cfg.channel("jawOpen").clamp == (0.0, 1.0)


def test_full_file_is_read_and_channels_match_any_spelling(tmp_path):
    path = tmp_path / "live.toml"
    path.write_text(FULL)
    cfg = load_live_config(path)
    assert cfg.filters["eyes"].min_cutoff == 4.0 and cfg.filters["eyes"].beta == 2.0
    assert cfg.filters["eyes"].d_cutoff == DEFAULT_FILTERS["eyes"].d_cutoff
    assert cfg.filters["head"].d_cutoff == 2.5 and cfg.filters["mouth"] == DEFAULT_FILTERS["mouth"]
    assert (cfg.timeout_s, cfg.ease_out_s, cfg.ease_in_s, cfg.capture_s) == (0.3, 1.0, 0.1, 0.75)
    assert cfg.channel("jawOpen").gain == 1.5 and cfg.channel("JAW_OPEN".lower()).gain == 1.0
    assert cfg.channel("jawOpen").clamp == (0.0, 0.9)
    assert cfg.channel("EyeBlinkLeft").gain == 0.5


@pytest.mark.parametrize("text, match", [
    ('[filter.eyes]\nbeta = "fast"', r"key 'filter.eyes.beta': expected a finite number, got 'fast' \(str\)"),
    ("[filter.mouth]\nmin_cutoff = 0", r"key 'filter.mouth.min_cutoff': expected a number > 0"),
    ("[filter.lips]\nbeta = 1", r"key 'filter.lips': unknown key; expected one of eyes, brows"),
    ("[tracking_loss]\ntimeout = 1", r"key 'tracking_loss.timeout': unknown key"),
    ("[channels.jawOpen]\nclamp = [1, 0]", r"key 'channels.jawOpen.clamp': expected low <= high"),
    ("[channels.jawOpen]\nclamp = 1", r"key 'channels.jawOpen.clamp': expected an array of two numbers"),
    ("[channels.jawOpen]\ngain = true", r"key 'channels.jawOpen.gain': expected a finite number, got True \(bool\)"),
    ("tracking_loss = 3", r"key 'tracking_loss': expected a table, got 3 \(int\)"),
    ("[filter.eyes\n", r"not valid TOML"),
])
def test_errors_name_the_file_the_key_and_what_was_expected(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(LiveConfigError, match=match) as info:
        load_live_config(path)
    assert str(path) in str(info.value)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_live_config(tmp_path / "absent.toml")


def test_a_5000_deep_array_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("[channels.jawOpen]\nclamp = " + "[" * 5000 + "]" * 5000 + "\n", encoding="utf-8")
    with pytest.raises(LiveConfigError, match=r"deep\.toml: not a config facepuppet can read: .*nest too deep"):
        load_live_config(path)


def test_a_config_that_is_not_utf8_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "latin.toml"
    path.write_bytes(b"# r\xe9glages\n[tracking_loss]\ntimeout_s = 0.5\n")
    with pytest.raises(LiveConfigError, match=r"latin\.toml: not UTF-8 text \(byte 3"):
        load_live_config(path)


def test_a_misspelt_channel_is_an_error_naming_the_close_matches(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text("[channels.jawOpne]\ngain = 1.3\n")
    with pytest.raises(LiveConfigError, match=r"typo.toml: key 'channels.jawOpne': no channel of that name; "
                                              r"did you mean jawOpen\?"):
        load_live_config(path)
    path.write_text("[channels.EyeBlinkLeftt]\ngain = 1.3\n")
    with pytest.raises(LiveConfigError, match=r"did you mean eyeBlinkLeft"):
        load_live_config(path)
    path.write_text("[channels.zzzz]\ngain = 1.3\n")
    with pytest.raises(LiveConfigError, match=r"'channels.zzzz': no channel of that name; expected an ARKit name"):
        load_live_config(path)


def test_channels_of_the_character_and_sides_of_unsided_arkit_channels_are_known(tmp_path):
    path = tmp_path / "ok.toml"
    path.write_text("[channels.browInnerUp_L]\ngain = 1.1\n[channels.cheekRaiser_R]\ngain = 0.9\n")
    with pytest.raises(LiveConfigError, match="cheekRaiser_R"):
        load_live_config(path)                                   # not ARKit, and no character named it
    cfg = load_live_config(path, known_channels=("cheekRaiser_L", "cheekRaiser_R"))
    assert cfg.channel("cheekRaiser_R").gain == 0.9 and cfg.channel("browInnerUp_L").gain == 1.1
