"""Channels onto a VRM-like character: morphs, expressions by name, the default ARKit -> VRM preset mapping.

Expected weights are worked out by hand in each test from the VRM0_FROM_ARKIT table (runtime/mapping/vrm_names.py
module doc), the bind weights of tests/helpers/vrm_characters.py and the VRM 1.0 expression rules.
"""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.live.config import LiveConfigError, load_live_config, parse_live_config
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, ChannelMap
from facepuppet.runtime.mapping.expressions import ExpressionDrive, MappingError, make_drive, preset_of

from helpers.small_characters import sphere_character
from helpers.vrm_characters import PRESET_EXPRESSIONS, preset_character, sync_character


def arkit(**values) -> np.ndarray:
    x = np.zeros(len(ARKIT_NAMES), np.float32)
    for name, v in values.items():
        x[ARKIT_NAMES.index(name)] = v
    return x


def shapes(character, weights) -> dict[str, float]:
    return {n: float(w) for n, w in zip(character.shape_names, weights)}


def drive_of(character, mapping=None) -> ExpressionDrive:
    return make_drive(character.shape_names, character.expressions, mapping)


FACE = dict(eyeBlinkLeft=0.9, eyeBlinkRight=0.4, jawOpen=0.6, mouthFunnel=0.4, mouthPucker=0.1,
            mouthStretchLeft=0.5, mouthStretchRight=0.3, mouthLowerDownLeft=0.2, mouthLowerDownRight=0.2,
            eyeLookUpLeft=0.3, eyeLookUpRight=0.5, eyeLookOutLeft=0.6, eyeLookInRight=0.2,
            mouthSmileLeft=0.8, mouthSmileRight=0.8, browDownLeft=0.6, browDownRight=0.6)


def test_a_preset_only_avatar_driven_by_arkit_gets_the_default_mapping_arithmetic():
    c = preset_character()
    m = drive_of(c).build(ARKIT_NAMES)
    got = shapes(c, m.apply(arkit(**FACE)))
    # Blink = min(0.9, 0.4) = 0.4, Blink_L = 0.5, Blink_R = 0: blink_left = 0.4 + 0.5, blink_right = 0.4
    # A = 0.6 - 0.5*0.4 - 0.5*0.1 = 0.35; O = 0.4 (funnel); ah = A*1 + O*0.5 = 0.55, oh = O*0.6 = 0.24
    # I = mean(0.5, 0.3) - 0.5*0.1 = 0.35, ih = I*0.8 = 0.28; U = 0.1 - 0.5*0.6 < 0 -> 0
    # E = 0.5*0.2 + 0.5*0.4 - 0.5*0.4 = 0.1; LookUp = mean(0.3, 0.5) = 0.4; LookLeft = 0.5*0.6 + 0.5*0.2 = 0.4
    # Joy (smile 0.8) and Angry (brows 0.6) are emotions: off by default -> smile, angled_eyebrows 0
    expected = dict(blink_left=0.9, blink_right=0.4, ah=0.55, ih=0.28, uu=0.0, ee=0.1, oh=0.24, look_up=0.4,
                    look_down=0.0, look_left=0.4, look_right=0.0, angled_eyebrows=0.0, smile=0.0, HideBlush=0.0)
    assert got == pytest.approx(expected, abs=1e-6)
    e = dict(zip(c.expressions.names, m.expression_values.tolist()))
    assert e["Blink"] == pytest.approx(0.4) and e["Blink_L"] == pytest.approx(0.5) and e["Blink_R"] == 0.0
    assert e["Joy"] == 0.0 and m.drives_expressions


def test_emotions_are_off_by_default_and_on_when_configured(tmp_path):
    c = preset_character()
    path = tmp_path / "emotions.toml"
    path.write_text("[mapping]\nemotions = true\n")
    cfg = load_live_config(path)
    m = drive_of(c, cfg.mapping).build(ARKIT_NAMES)
    got = shapes(c, m.apply(arkit(**FACE)))
    # Joy = mean(smile) = 0.8 -> smile = Joy*1 + Fun*0.5 (Fun = cheekSquint = 0); Angry = 0.6 -> brows 0.6*0.5
    assert got["smile"] == pytest.approx(0.8) and got["angled_eyebrows"] == pytest.approx(0.3)
    off = drive_of(c).build(ARKIT_NAMES)
    assert "emotions = true" in off.report() and "mouthSmileLeft" in off.unmatched_source


def test_blinks_on_an_avatar_with_only_blink_or_only_the_sides():
    c = preset_character()
    only_blink = [r for r in PRESET_EXPRESSIONS if r[0] not in ("Blink_L", "Blink_R")]
    c1 = preset_character(table=only_blink)
    got = shapes(c1, drive_of(c1).build(ARKIT_NAMES).apply(arkit(eyeBlinkLeft=0.9, eyeBlinkRight=0.4)))
    assert got["blink_left"] == pytest.approx(0.65) and got["blink_right"] == pytest.approx(0.65)  # the mean
    sides = [r for r in PRESET_EXPRESSIONS if r[0] != "Blink"]
    c2 = preset_character(table=sides)
    got = shapes(c2, drive_of(c2).build(ARKIT_NAMES).apply(arkit(eyeBlinkLeft=0.9, eyeBlinkRight=0.4)))
    assert got["blink_left"] == pytest.approx(0.9) and got["blink_right"] == pytest.approx(0.4)
    assert c.n_expressions == 18


def test_a_perfect_sync_avatar_is_driven_directly_and_its_expressions_do_not_add():
    c = sync_character()
    names = tuple("EyeBlinkLeft EyeBlinkRight JawOpen MouthFunnel MouthSmileLeft BrowInnerUp".split())
    m = drive_of(c).build(names)
    got = shapes(c, m.apply(np.array([0.9, 0.4, 0.6, 0.3, 0.2, 0.5], np.float32)))
    # every ARKit channel has its morph: straight through; Blink and A are not driven (no default mapping)
    assert got == pytest.approx(dict(eyeBlink_L=0.9, eyeBlink_R=0.4, jawOpen=0.6, mouthFunnel=0.3,
                                     mouthPucker=0.0, mouthSmile_L=0.2, mouthSmile_R=0.0, browInnerUp=0.5))
    assert set(m.routes) == {"morph"} and not m.drives_expressions
    # the same through a plain ChannelMap (what the character gives without expressions)
    np.testing.assert_array_equal(m.apply(np.full(6, 0.5, np.float32)),
                                  ChannelMap.build(names, c.shape_names).apply(np.full(6, 0.5, np.float32)))


def test_a_shape_driven_directly_and_through_an_expression_takes_the_direct_value():
    c = sync_character()
    m = drive_of(c).build(("JawOpen", "A", "Blink"))
    got = shapes(c, m.apply(np.array([0.2, 1.0, 0.5], np.float32)))
    # A binds jawOpen at 0.7, but jawOpen is driven directly: 0.2; Blink reaches both eyelids at 0.5
    assert got["jawOpen"] == pytest.approx(0.2)
    assert got["eyeBlink_L"] == pytest.approx(0.5) and got["eyeBlink_R"] == pytest.approx(0.5)
    assert m.routes == ("morph", "expression", "expression")


@pytest.mark.parametrize("spelling, preset", [
    ("A", "A"), ("a", "A"), ("aa", "A"), ("AA", "A"), ("Blink_L", "Blink_L"), ("blink_l", "Blink_L"),
    ("blinkLeft", "Blink_L"), ("Joy", "Joy"), ("happy", "Joy"), ("sad", "Sorrow"), ("relaxed", "Fun"),
    ("lookleft", "LookLeft"), ("neutral", "Neutral"), ("jawOpen", None), ("surprised", None),
])
def test_preset_spellings(spelling, preset):
    assert preset_of(spelling) == preset


def test_preset_names_in_both_vrm_spellings_drive_the_expressions():
    c = preset_character()
    names = ("Blink_L", "aa", "happy", "blink_r", "OH", "hideblush")
    m = drive_of(c).build(names)
    got = shapes(c, m.apply(np.array([0.7, 0.5, 0.3, 0.2, 0.4, 1.0], np.float32)))
    # Blink_L -> blink_left 0.7; aa = A 0.5 and OH = O 0.4 -> ah = 0.5 + 0.4*0.5 = 0.7, oh = 0.4*0.6 = 0.24
    # happy = Joy 0.3 (named: emotions-off concerns only the default mapping) -> smile 0.3; blink_r -> 0.2
    # hideblush: the custom expression HideBlush, any case -> HideBlush 1
    assert got["blink_left"] == pytest.approx(0.7) and got["blink_right"] == pytest.approx(0.2)
    assert got["ah"] == pytest.approx(0.7) and got["oh"] == pytest.approx(0.24)
    assert got["smile"] == pytest.approx(0.3) and got["HideBlush"] == pytest.approx(1.0)
    assert m.routes == ("expression",) * 6


def test_a_named_preset_wins_over_the_default_mapping_only_in_frames_that_send_it():
    c = preset_character()
    names = (*ARKIT_NAMES, "Blink")
    m = drive_of(c).build(names)
    x = np.append(arkit(eyeBlinkLeft=0.2, eyeBlinkRight=0.2), np.float32(np.nan))  # Blink not sent
    assert shapes(c, m.apply(x))["blink_left"] == pytest.approx(0.2)  # Blink = min(0.2, 0.2) from ARKit
    x[-1] = 1.0
    assert shapes(c, m.apply(x))["blink_left"] == pytest.approx(1.0)  # Blink sent: 1 (+ Blink_L 0)


def test_several_channels_naming_one_expression_take_their_maximum():
    c = preset_character()
    m = drive_of(c).build(("Joy", "happy"))
    assert shapes(c, m.apply(np.array([0.2, 0.6], np.float32)))["smile"] == pytest.approx(0.6)
    assert shapes(c, m.apply(np.array([0.7, np.nan], np.float32)))["smile"] == pytest.approx(0.7)


def test_several_expressions_on_one_shape_add_and_clip():
    c = preset_character()
    m = drive_of(c).build(("Joy", "Fun", "A", "O"))
    got = shapes(c, m.apply(np.array([0.6, 0.4, 0.9, 0.8], np.float32)))
    assert got["smile"] == pytest.approx(0.6 + 0.4 * 0.5)  # Joy*1 + Fun*0.5
    assert got["ah"] == 1.0  # A*1 + O*0.5 = 1.3, clipped


def test_is_binary_thresholds_above_one_half():
    c = preset_character(flags={"A": (True, "none", "none", "none")})
    m = drive_of(c).build(("A",))
    assert shapes(c, m.apply(np.array([0.5], np.float32)))["ah"] == 0.0  # "greater than 0.5 is 1.0"
    assert shapes(c, m.apply(np.array([0.51], np.float32)))["ah"] == 1.0
    assert shapes(c, m.apply(np.array([0.2], np.float32)))["ah"] == 0.0


def test_block_override_sets_the_group_to_zero_while_the_overrider_is_above_zero():
    c = preset_character(flags={"Joy": (False, "block", "none", "none")})
    m = drive_of(c).build(("Joy", "Blink", "A"))
    got = shapes(c, m.apply(np.array([0.01, 1.0, 0.8], np.float32)))
    assert got["blink_left"] == 0.0 and got["blink_right"] == 0.0  # blink group blocked
    assert got["ah"] == pytest.approx(0.8) and got["smile"] == pytest.approx(0.01)  # mouth untouched
    got = shapes(c, m.apply(np.array([0.0, 1.0, 0.8], np.float32)))
    assert got["blink_left"] == 1.0


def test_blend_override_scales_the_group_by_one_minus_the_summed_weights():
    c = preset_character(flags={"Joy": (False, "none", "none", "blend"), "Angry": (False, "none", "none", "blend")})
    m = drive_of(c).build(("Joy", "Angry", "A", "I"))
    got = shapes(c, m.apply(np.array([0.25, 0.15, 0.8, 0.5], np.float32)))
    f = 1 - (0.25 + 0.15)  # factor = 1 - saturate(0.4)
    assert got["ah"] == pytest.approx(0.8 * f) and got["ih"] == pytest.approx(0.5 * f * 0.8)
    got = shapes(c, m.apply(np.array([0.7, 0.6, 0.8, 0.5], np.float32)))
    assert got["ah"] == 0.0  # saturated at 1


def test_overrides_of_the_same_kind_are_ignored_and_binary_rules_hold():
    # Blink overriding blink is "treated as invalid"; a binary overrider acts with its binary value;
    # an overridden binary expression is suppressed completely when the effect is > 0
    c = preset_character(flags={"Blink": (True, "block", "none", "none"), "Joy": (True, "blend", "none", "none"),
                                "Angry": (False, "blend", "none", "none")})
    m = drive_of(c).build(("Blink", "Joy", "Angry"))
    assert shapes(c, m.apply(np.array([0.9, 0.0, 0.0], np.float32)))["blink_left"] == 1.0  # not self-blocked
    assert shapes(c, m.apply(np.array([0.9, 0.4, 0.0], np.float32)))["blink_left"] == 1.0  # Joy binary 0
    assert shapes(c, m.apply(np.array([0.9, 0.6, 0.0], np.float32)))["blink_left"] == 0.0  # Joy binary 1
    assert shapes(c, m.apply(np.array([0.9, 0.0, 0.1], np.float32)))["blink_left"] == 0.0  # 0.9 factor: binary -> 0


def test_config_overrides_a_channel_onto_another_expression_or_a_morph_or_off(tmp_path):
    c = preset_character()
    path = tmp_path / "map.toml"
    path.write_text('[mapping.channels]\njawOpen = { to = "oh", weight = 0.5 }\neyeLookOutLeft = false\n'
                    'tongueOut = "HideBlush"\nmouthSmile_L = [{ to = "Joy", weight = 0.5 }, { to = "ee" }]\n')
    cfg = load_live_config(path, c.shape_names)
    m = drive_of(c, cfg.mapping).build(ARKIT_NAMES)
    got = shapes(c, m.apply(arkit(jawOpen=0.6, eyeLookOutLeft=0.6, eyeLookInRight=0.2, tongueOut=0.7,
                                  mouthSmileLeft=0.4)))
    # jawOpen -> O at 0.5 only (no longer A or U): O = 0.3 -> oh = 0.18, ah = O*0.5 = 0.15
    # eyeLookOutLeft off: LookLeft = 0.5*0.2 = 0.1; tongueOut -> the HideBlush morph directly
    # mouthSmileLeft -> Joy 0.2 (smile 0.2) and E 0.4 (ee 0.4)
    assert got["oh"] == pytest.approx(0.18) and got["ah"] == pytest.approx(0.15)
    assert got["look_left"] == pytest.approx(0.1) and got["HideBlush"] == pytest.approx(0.7)
    assert got["smile"] == pytest.approx(0.2) and got["ee"] == pytest.approx(0.4)
    routes = dict(zip(ARKIT_NAMES, m.routes))
    assert routes["jawOpen"] == routes["eyeLookOutLeft"] == routes["tongueOut"] == "config"
    assert "eyeLookOutLeft→nothing (off)" in m.report() and "jawOpen→O×0.5" in m.report()


def test_config_mapping_errors_name_the_file_and_key(tmp_path):
    c = preset_character()
    path = tmp_path / "bad.toml"
    path.write_text('[mapping.channels]\njawOpen = { to = "nowhere" }\n')
    cfg = load_live_config(path)
    with pytest.raises(MappingError, match=r"bad.toml: key 'mapping.channels.jawOpen': target 'nowhere' is "
                                           r"neither an expression nor a shape"):
        drive_of(c, cfg.mapping)
    for text, match in [('[mapping]\nemotions = "yes"\n', "mapping.emotions': expected true or false"),
                        ('[mapping.channels]\njawOpen = 3\n', "mapping.channels.jawOpen': expected false, a target"),
                        ('[mapping.channels]\njawOpen = { to = "A", weight = "x" }\n',
                         "mapping.channels.jawOpen.weight': expected a finite number"),
                        ('[mapping.channels]\njawOpen = []\n', "an empty array"),
                        ('[mapping.channels]\njawOpn = "A"\n', "mapping.channels.jawOpn': no channel .*jawOpen"),
                        ('[mapping]\nemotion = true\n', "mapping.emotion': unknown key")]:
        path.write_text(text)
        with pytest.raises(LiveConfigError, match=match):
            load_live_config(path)


def test_the_report_names_the_route_of_each_channel():
    c = preset_character()
    names = ("eyeBlinkLeft", "Blink_R", "ah", "tongueOut")
    m = drive_of(c).build(names)
    assert m.routes == ("default preset mapping", "expression", "morph", "")
    report = m.report()
    assert "default preset mapping (1): eyeBlinkLeft→Blink+Blink_L" in report
    assert "expression (1): Blink_R→Blink_R" in report and "morph (1): ah→ah" in report
    assert "1 source channel(s) have no shape or expression on this character and are ignored: tongueOut" in report
    assert m.unmatched_source == ("tongueOut",)
    assert "look_up" in m.undriven_target and "blink_right" not in m.undriven_target


def test_a_character_without_expressions_keeps_the_plain_channel_map():
    c = sphere_character()
    assert make_drive(c.shape_names, None) is None
    assert make_drive(c.shape_names, None, parse_live_config({}).mapping) is None
    cfg = parse_live_config({"mapping": {"channels": {"mouthFunnel": "puff"}}})
    d = make_drive(c.shape_names, None, cfg.mapping)  # a [mapping] still applies to a plain rig's shapes
    m = d.build(("JawOpen", "MouthFunnel"))
    np.testing.assert_allclose(m.apply(np.array([0.3, 0.6], np.float32)), [0.3, 0.6])


def test_nan_counts_as_zero_for_morphs_and_the_map_writes_into_out():
    c = preset_character()
    m = drive_of(c).build(("ah", "Blink"))
    out = np.full(c.n_shapes, 9.0, np.float32)
    assert m.apply(np.array([np.nan, np.nan], np.float32), out=out) is out
    np.testing.assert_array_equal(out, 0.0)


def test_a_direct_channel_left_out_of_a_frame_lets_the_expressions_drive_its_shape():
    """A VMC sender of VRM presets only: its frames carry the 52 ARKit channels unsent (NaN). On a perfect-sync
    avatar the Blink expression must then close the eyelids, though eyeBlinkLeft drives them directly when sent."""
    c = sync_character()
    m = drive_of(c).build(("EyeBlinkLeft", "EyeBlinkRight", "Blink"))
    got = shapes(c, m.apply(np.array([np.nan, np.nan, 0.7], np.float32)))
    assert got["eyeBlink_L"] == pytest.approx(0.7) and got["eyeBlink_R"] == pytest.approx(0.7)
    got = shapes(c, m.apply(np.array([0.2, np.nan, 0.7], np.float32)))
    assert got["eyeBlink_L"] == pytest.approx(0.2) and got["eyeBlink_R"] == pytest.approx(0.7)  # sent: direct wins


def test_expressions_named_like_arkit_shapes_come_through_the_arkit_channels():
    """A perfect-sync VRM avatar has clips named like the 52 (EyeBlinkLeft binding its eyeBlink_L morph): VMC does
    not get them as extra channels (they would steal the ARKit name), and the ARKit channel reaches the clip."""
    from helpers.vrm_characters import expressions_of, morph_character

    base = morph_character(("eyeBlink_L", "jawOpen", "ah"))
    c = base.with_parts(expressions=expressions_of(base.shape_names, (
        ("EyeBlinkLeft", "", (("eyeBlink_L", 1.0),)), ("JawOpen", "", (("jawOpen", 0.5), ("ah", 1.0))),
        ("A", "A", (("ah", 1.0),)))))
    d = drive_of(c)
    assert d.receive_names() == ("A",)
    m = d.build(ARKIT_NAMES)
    got = shapes(c, m.apply(arkit(eyeBlinkLeft=0.6, jawOpen=0.8)))
    assert got == pytest.approx(dict(eyeBlink_L=0.6, jawOpen=0.4, ah=0.8))  # the clip's binds, not the raw morph
    routes = dict(zip(ARKIT_NAMES, m.routes))
    assert routes["eyeBlinkLeft"] == routes["jawOpen"] == "expression"


def test_a_stage_writing_the_characters_own_shapes_drives_them_as_shapes():
    """Kernel PLS and the marker solve's pair table write the character's shapes in order: the values are shape
    weights, even where a shape shares a name with an expression (HideBlush) or looks like an ARKit channel."""
    c = preset_character()
    m = drive_of(c).build(c.shape_names)
    x = np.linspace(0.05, 0.7, c.n_shapes).astype(np.float32)
    np.testing.assert_array_equal(m.apply(x), x)
    assert set(m.routes) == {"morph"} and not m.drives_expressions
