"""VMC adapter fed with crafted datagrams (no sockets): values, names, poses, counters."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from facepuppet.runtime.inputs.vmc import PRESETS, VmcAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import bundle, counts, msg

VAL, APPLY = "/VMC/Ext/Blend/Val", "/VMC/Ext/Blend/Apply"
INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}


def blend(*pairs):
    """One bundle: Val per (name, value), then Apply."""
    return bundle(*(msg(VAL, n, v) for n, v in pairs), msg(APPLY))


def test_val_then_apply_gives_jaw_open_and_nan_elsewhere():
    a = VmcAdapter()
    f = a.handle(blend(("JawOpen", 0.7)), 3.5)
    assert f.channels == ARKIT_NAMES and f.source == "vmc" and f.t == 3.5
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.7)
    assert np.isnan(np.delete(f.weights, INDEX["jawOpen"])).all()
    assert f.head_rotation is None and math.isnan(f.t_sender)
    counts(a, datagrams=1, frames=1)


def test_values_take_effect_at_apply_in_separate_datagrams():
    a = VmcAdapter()
    assert a.handle(msg(VAL, "JawOpen", 0.3).dgram, 1.0) is None
    assert a.handle(msg(VAL, "MouthFunnel", 0.4).dgram, 1.1) is None
    f = a.handle(msg(APPLY).dgram, 1.2)
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.3)
    assert f.weights[INDEX["mouthFunnel"]] == pytest.approx(0.4)
    g = a.handle(blend(("EyeBlinkLeft", 1.0)), 2.0)  # a new frame starts empty
    assert np.isnan(g.weights[INDEX["jawOpen"]]) and g.weights[INDEX["eyeBlinkLeft"]] == 1.0
    counts(a, datagrams=4, frames=2)


@pytest.mark.parametrize("name, expected", [
    ("Blink", {"eyeBlinkLeft": 0.8, "eyeBlinkRight": 0.8}),
    ("blink", {"eyeBlinkLeft": 0.8, "eyeBlinkRight": 0.8}),
    ("Blink_L", {"eyeBlinkLeft": 0.8}),
    ("blinkRight", {"eyeBlinkRight": 0.8}),
    ("A", {"jawOpen": 0.8}),
    ("aa", {"jawOpen": 0.8}),
    ("O", {"mouthFunnel": 0.8, "jawOpen": 0.16}),
    ("ou", {"mouthPucker": 0.8}),
    ("I", {"mouthStretchLeft": 0.48, "mouthStretchRight": 0.48, "jawOpen": 0.12}),
    ("ee", {"mouthStretchLeft": 0.32, "mouthStretchRight": 0.32, "jawOpen": 0.24}),
    ("Joy", {"mouthSmileLeft": 0.8, "mouthSmileRight": 0.8}),
    ("happy", {"mouthSmileLeft": 0.8, "mouthSmileRight": 0.8}),
    ("Angry", {"browDownLeft": 0.8, "browDownRight": 0.8}),
    ("sad", {"mouthFrownLeft": 0.8, "mouthFrownRight": 0.8, "browInnerUp": 0.8}),
    ("Fun", {"mouthSmileLeft": 0.4, "mouthSmileRight": 0.4}),
    ("surprised", {"eyeWideLeft": 0.8, "eyeWideRight": 0.8, "browInnerUp": 0.8, "jawOpen": 0.24}),
    ("LookUp", {"eyeLookUpLeft": 0.8, "eyeLookUpRight": 0.8}),
    ("lookLeft", {"eyeLookOutLeft": 0.8, "eyeLookInRight": 0.8}),
    ("LookRight", {"eyeLookInLeft": 0.8, "eyeLookOutRight": 0.8}),
    ("EyeBlinkLeft", {"eyeBlinkLeft": 0.8}),
    ("TongueOut", {"tongueOut": 0.8}),
])
def test_presets_and_perfect_sync_names_map_to_arkit(name, expected):
    f = VmcAdapter().handle(blend((name, 0.8)), 0.0)
    got = {ARKIT_NAMES[i]: float(v) for i, v in enumerate(f.weights) if not np.isnan(v)}
    assert got == pytest.approx(expected)


def test_every_preset_targets_arkit_channels():
    for name, targets in PRESETS.items():
        assert targets and all(c in INDEX for c, _ in targets), name


def test_names_are_case_sensitive_and_unmapped_names_are_counted():
    a = VmcAdapter()
    f = a.handle(blend(("joy", 1.0), ("JOY", 1.0), ("Neutral", 1.0), ("まばたき", 1.0)), 0.0)
    assert np.isnan(f.weights).all()
    counts(a, datagrams=1, frames=1, unmapped_name=4)


def test_perfect_sync_wins_over_presets_and_presets_combine_by_max():
    for pairs in ((("A", 1.0), ("JawOpen", 0.2)), (("JawOpen", 0.2), ("A", 1.0))):
        f = VmcAdapter().handle(blend(*pairs), 0.0)
        assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.2)
    f = VmcAdapter().handle(blend(("Joy", 0.3), ("happy", 0.6), ("Fun", 1.0)), 0.0)
    assert f.weights[INDEX["mouthSmileLeft"]] == pytest.approx(0.6)


def test_head_bone_is_converted_kept_and_attached_other_bones_ignored():
    a = VmcAdapter()
    s = math.sqrt(0.5)
    pose = bundle(msg("/VMC/Ext/Bone/Pos", "Head", 0.1, 1.5, 0.2, 0.0, s, 0.0, s),
                  msg("/VMC/Ext/Bone/Pos", "LeftHand", 9.0, 9.0, 9.0, 0.0, 0.0, 0.0, 1.0))
    assert a.handle(pose, 1.0) is None
    f = a.handle(blend(("JawOpen", 0.1)), 1.1)
    assert f.head_translation is None  # a bone's position is its local offset from the neck, not a motion
    np.testing.assert_allclose(f.head_rotation, [0.0, -s, 0.0, s], rtol=1e-6)  # Unity -> ours: x mirrored
    g = a.handle(blend(("JawOpen", 0.2)), 1.2)
    np.testing.assert_array_equal(g.head_rotation, f.head_rotation)
    counts(a, datagrams=3, frames=2)


def test_root_ok_and_time_are_kept_extra_args_ignored():
    a = VmcAdapter()
    root = msg("/VMC/Ext/Root/Pos", "root", 1.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0)
    a.handle(bundle(root, msg("/VMC/Ext/OK", 1, 3, 0, 1, 99), msg("/VMC/Ext/T", 12.5)), 0.0)
    np.testing.assert_allclose(a.root_position, [-1.0, 0.0, 2.0])
    np.testing.assert_allclose(a.root_rotation, [0.0, 0.0, 0.0, 1.0])
    assert a.status == {"loaded": 1, "calib_state": 3, "calib_mode": 0, "tracking": 1}
    f = a.handle(blend(("JawOpen", 0.5)), 0.1)
    assert f.t_sender == 12.5
    extra = a.handle(bundle(msg(VAL, "JawOpen", 0.6, "surplus", 7), msg(APPLY, 1)), 0.2)
    assert extra.weights[INDEX["jawOpen"]] == pytest.approx(0.6)
    counts(a, datagrams=3, frames=2)


def test_integer_values_are_accepted_as_floats():
    f = VmcAdapter().handle(blend(("JawOpen", 1)), 0.0)
    assert f.weights[INDEX["jawOpen"]] == 1.0


@pytest.mark.parametrize("message", [
    msg(VAL, 0.5, 0.5),                      # name is not a string
    msg(VAL, "JawOpen"),                     # value missing
    msg(VAL, "JawOpen", "0.5"),              # value is a string
    msg(VAL, "JawOpen", True),               # value is a boolean
    msg(VAL),                                # no arguments
    msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),  # 6 floats, 7 needed
    msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, "x", 0.0, 0.0, 0.0, 1.0),
    msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),  # zero quaternion
    msg("/VMC/Ext/Bone/Pos", 3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    msg("/VMC/Ext/Root/Pos", "root", 0.0),
    msg("/VMC/Ext/OK", 1.0),
    msg("/VMC/Ext/OK"),
    msg("/VMC/Ext/T", "now"),
])
def test_wrong_types_and_too_few_arguments_are_malformed(message):
    a = VmcAdapter()
    a.handle(bundle(msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)), 0.0)
    assert a.handle(message.dgram, 1.0) is None
    f = a.handle(blend(("JawOpen", 0.25)), 2.0)  # still works, pose unchanged
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.25)
    np.testing.assert_array_equal(f.head_rotation, [0, 0, 0, 1])
    counts(a, datagrams=3, frames=1, malformed=1)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, (1e300, "d")])  # a double past float32
def test_nonfinite_value_rejects_the_frame(bad):
    a = VmcAdapter()
    assert a.handle(blend(("JawOpen", 0.5), ("MouthFunnel", bad)), 0.0) is None
    head = msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.0, 0.0, 0.0, 0.0, bad, 1.0)
    assert a.handle(head.dgram, 0.5) is None
    f = a.handle(blend(("MouthFunnel", 0.1)), 1.0)
    assert f.weights[INDEX["mouthFunnel"]] == pytest.approx(0.1) and np.isnan(f.weights[INDEX["jawOpen"]])
    assert f.head_rotation is None
    counts(a, datagrams=3, frames=1, nonfinite=2)


def test_unknown_addresses_are_ignored_and_counted():
    a = VmcAdapter()
    f = a.handle(bundle(msg("/VMC/Ext/Light", "Light", 0.0), msg("/VMC/Ext/Set/Period", 1, 1, 1, 1, 1, 1),
                        msg("/something/else"), msg(VAL, "JawOpen", 0.4), msg(APPLY)), 0.0)
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.4)
    counts(a, datagrams=1, frames=1, unknown_address=3)


@pytest.mark.parametrize("data", [
    b"",
    b"/VMC",                                       # unterminated address
    b"/VMC/Ext/Blend/Val\x00\x00,sf\x00JawOpen\x00",  # float missing
    b"/VMC/Ext/Blend/Val\x00\x00sf\x00\x00",       # type tags without ","
    b"#bundle\x00\x00\x00",                        # truncated time tag
    b"#bundle\x00" + bytes(8) + struct.pack(">i", -4),  # negative element size
    b"#bundle\x00" + bytes(8) + struct.pack(">i", 400) + b"/VMC",  # element past the end
    b"\xff\xfe garbage",
])
def test_unparseable_datagrams_are_counted_as_malformed(data):
    a = VmcAdapter()
    assert a.handle(data, 0.0) is None
    counts(a, datagrams=1, malformed=1)


def test_truncations_of_a_valid_bundle_never_raise():
    a = VmcAdapter()
    data = blend(("JawOpen", 0.5), ("Joy", 1.0))
    boundaries, pos = [16], 16  # a cut at an element boundary leaves a shorter valid bundle
    while pos < len(data):
        pos += 4 + struct.unpack_from(">i", data, pos)[0]
        boundaries.append(pos)
    assert boundaries[-1] == len(data) and len(boundaries) == 4
    for n in range(len(data)):
        assert a.handle(data[:n], float(n)) is None  # no Apply survives a cut
    counts(a, datagrams=len(data), malformed=len(data) - 3)


def test_oversized_datagram_is_counted():
    a = VmcAdapter()
    assert a.handle(b"/" + bytes(70000), 0.0) is None
    counts(a, datagrams=1, oversized=1)


def test_the_avatars_expression_names_arrive_as_their_own_channels_in_any_vrm_spelling():
    """A character with VRM expressions gives the adapter their names (build_chain): a preset name in its VRM 0.x
    or 1.0 spelling, any case, reaches the expression's channel instead of the ARKit approximation."""
    a = VmcAdapter(extra_names=("Blink", "Blink_L", "A", "Joy", "HideBlush"))
    f = a.handle(blend(("happy", 0.4), ("blinkLeft", 0.7), ("aa", 0.3), ("HideBlush", 1.0), ("JawOpen", 0.2)), 1.0)
    at = {name: i for i, name in enumerate(f.channels)}
    assert f.channels[:52] == ARKIT_NAMES and f.channels[52:] == ("Blink", "Blink_L", "A", "Joy", "HideBlush")
    assert f.weights[at["Joy"]] == pytest.approx(0.4) and f.weights[at["Blink_L"]] == pytest.approx(0.7)
    assert f.weights[at["A"]] == pytest.approx(0.3) and f.weights[at["HideBlush"]] == 1.0
    assert np.isnan(f.weights[at["Blink"]])  # not sent
    # not also turned into ARKit channels: the smile and the eyelid stay unsent, the jaw is the perfect-sync value
    assert np.isnan(f.weights[INDEX["mouthSmileLeft"]]) and np.isnan(f.weights[INDEX["eyeBlinkLeft"]])
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.2)
    g = a.handle(blend(("Joy", 0.9), ("Sorrow", 0.5)), 2.0)  # Sorrow: not the avatar's -> the ARKit approximation
    assert g.weights[at["Joy"]] == pytest.approx(0.9) and g.weights[INDEX["browInnerUp"]] == pytest.approx(0.5)
    counts(a, datagrams=2, frames=2)


def _unity_turn(axis: int, degrees: float) -> list[float]:
    q = [0.0, 0.0, 0.0, math.cos(math.radians(degrees) / 2)]
    q[axis] = math.sin(math.radians(degrees) / 2)
    return q


def test_eye_bones_give_the_eye_look_weights_the_blend_values_did_not_send():
    a = VmcAdapter()
    # Unity: +20 deg about +y turns the eyes to the avatar's right (x is its right there): the left eye in,
    # the right eye out; +15 deg about +x looks down. 30 deg is weight 1, as the phone adapters write angles.
    a.handle(bundle(msg("/VMC/Ext/Bone/Pos", "LeftEye", 0.03, 0.05, 0.0, *_unity_turn(1, 20.0)),
                    msg("/VMC/Ext/Bone/Pos", "RightEye", -0.03, 0.05, 0.0, *_unity_turn(1, 20.0))), 1.0)
    f = a.handle(blend(("JawOpen", 0.1)), 1.1)
    w = dict(zip(f.channels, f.weights))
    assert w["eyeLookInLeft"] == pytest.approx(20 / 30, abs=1e-5)
    assert w["eyeLookOutRight"] == pytest.approx(20 / 30, abs=1e-5)
    assert w["eyeLookOutLeft"] == 0 and w["eyeLookInRight"] == 0 and w["eyeLookUpLeft"] == 0
    assert f.head_rotation is None  # eye bones do not turn the head
    a.handle(bundle(msg("/VMC/Ext/Bone/Pos", "LeftEye", 0.0, 0.0, 0.0, *_unity_turn(0, 15.0))), 1.2)
    f = a.handle(blend(("EyeLookDownLeft", 0.9)), 1.3)  # a sent weight wins over the bone's
    w = dict(zip(f.channels, f.weights))
    assert w["eyeLookDownLeft"] == pytest.approx(0.9) and w["eyeLookInLeft"] == pytest.approx(0.0, abs=1e-5)
    assert w["eyeLookInRight"] == 0 and w["eyeLookOutRight"] == pytest.approx(20 / 30, abs=1e-5)
    a.handle(bundle(msg("/VMC/Ext/Bone/Pos", "LeftEye", 0.0, 0.0, 0.0, *_unity_turn(0, 15.0))), 1.4)
    f = a.handle(blend(("JawOpen", 0.1)), 1.5)
    assert dict(zip(f.channels, f.weights))["eyeLookDownLeft"] == pytest.approx(0.5, abs=1e-5)
