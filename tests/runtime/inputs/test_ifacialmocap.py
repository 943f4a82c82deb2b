"""iFacialMocap datagrams crafted from the published facts (helpers.phone_senders), field by field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.inputs.ifacialmocap import MAX_PACKET, IFacialMocapAdapter
from facepuppet.runtime.inputs.kinds import INPUT_KINDS, default_port
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

from helpers.phone_senders import ARKIT_52, IFM_START, ifm_frame, ifm_name

DROPS = ("frames", "malformed", "oversized", "nonfinite", "internal_error")


def outcome(adapter) -> dict:
    return {k: adapter.counters[k] for k in DROPS}


def test_registered_with_its_default_port_and_start_payload():
    assert INPUT_KINDS["ifacialmocap"] is IFacialMocapAdapter and default_port("ifacialmocap") == 49983
    assert IFacialMocapAdapter.phone_port == 49983
    assert IFacialMocapAdapter.phone_request(1234) == IFM_START + b"|sendDataVersion=v2"


@pytest.mark.parametrize("version", [1, 2])
def test_every_blendshape_reaches_its_channel_scaled_to_0_1(version):
    values = {name: i + 1 for i, name in enumerate(ARKIT_52)}  # 1 .. 52, each name its own value
    frame = IFacialMocapAdapter().handle(ifm_frame(values, version=version), 5.0)
    assert frame is not None and frame.channels == ARKIT_NAMES and frame.t == 5.0 and frame.source == "ifacialmocap"
    for name, v in values.items():
        assert frame.weights[ARKIT_NAMES.index(name)] == pytest.approx(v / 100, abs=1e-7), name


def test_sides_come_from_the_L_R_suffix_and_directions_keep_theirs():
    assert ifm_name("eyeBlinkLeft") == "eyeBlink_L" and ifm_name("jawLeft") == "jawLeft"
    frame = IFacialMocapAdapter().handle(b"eyeBlink_L-100|eyeBlink_R-0|jawLeft-40|mouthRight-20|", 0.0)
    w = dict(zip(frame.channels, frame.weights.tolist()))
    assert w["eyeBlinkLeft"] == 1.0 and w["eyeBlinkRight"] == 0.0
    assert w["jawLeft"] == pytest.approx(0.4) and w["mouthRight"] == pytest.approx(0.2)
    assert sum(not math.isnan(x) for x in w.values()) == 4  # the rest: not sent (NaN), never 0


def test_v2_negative_values_and_v1_positive_values():
    frame = IFacialMocapAdapter().handle(ifm_frame({"jawOpen": -5, "cheekPuff": 30}, version=2), 0.0)
    assert frame.weights[ARKIT_NAMES.index("jawOpen")] == pytest.approx(-0.05)
    assert frame.weights[ARKIT_NAMES.index("cheekPuff")] == pytest.approx(0.3)


def test_head_rotation_in_degrees_and_translation():
    frame = IFacialMocapAdapter().handle(ifm_frame({"jawOpen": 1}, head=(10, -20, 5, 0.5, -1.5, 2.25)), 0.0)
    expected = euler_to_quat(math.radians(-20), math.radians(10), math.radians(5))  # yaw ry, pitch rx, roll rz
    np.testing.assert_allclose(frame.head_rotation, expected, atol=1e-6)
    np.testing.assert_allclose(frame.head_translation, (0.5, -1.5, 2.25))
    no_eq = IFacialMocapAdapter().handle(b"jawOpen-1|head#10,-20,5,0.5,-1.5,2.25|", 0.0)  # without '='
    np.testing.assert_allclose(no_eq.head_rotation, expected, atol=1e-6)


def test_eye_angles_fill_only_the_gaze_weights_not_sent():
    a = IFacialMocapAdapter()
    frame = a.handle(ifm_frame({"jawOpen": 10}, right_eye=(15, 0, 0), left_eye=(0, 30, 0)), 0.0)
    w = dict(zip(frame.channels, frame.weights.tolist()))
    assert w["eyeLookDownRight"] == pytest.approx(0.5) and w["eyeLookUpRight"] == 0.0  # 15 deg of 30 down
    assert w["eyeLookOutLeft"] == pytest.approx(1.0) and w["eyeLookInLeft"] == 0.0  # towards the face's left
    assert a.eyes["Right"] == (15, 0, 0) and a.eyes["Left"] == (0, 30, 0)
    sent = a.handle(ifm_frame({"eyeLookDownRight": 20}, right_eye=(15, 0, 0)), 0.0)
    assert sent.weights[ARKIT_NAMES.index("eyeLookDownRight")] == pytest.approx(0.2)  # what was sent wins


def test_unknown_keys_are_ignored_and_counted_per_item():
    a = IFacialMocapAdapter()
    frame = a.handle(ifm_frame({"jawOpen": 50}, version=1, extra="hapihapi-0|FM_browDown_L-3|"), 0.0)
    assert frame is not None and a.counters["unknown_key"] == 2 and a.counters["frames"] == 1
    assert frame.weights[ARKIT_NAMES.index("jawOpen")] == pytest.approx(0.5)


@pytest.mark.parametrize("data, counter", [
    (b"", "malformed"),
    (b"|||", "malformed"),                                   # no channel and no head
    (b"hapihapi-0|", "malformed"),                           # only unknown keys: nothing to draw
    (b"jawOpen-abc|", "malformed"),                          # value not a number
    (b"jawOpen-|", "malformed"),
    (b"jawOpen|", "malformed"),                              # no separator
    (b"jawOpen-1|jawOpen-2|", "malformed"),                  # the same name twice
    (b"jawOpen-1|=head#1,2,3,4,5|", "malformed"),            # head: 5 numbers, not 6
    (b"jawOpen-1|=head#1,2,3,4,5,6,7|", "malformed"),
    (b"jawOpen-1|rightEye#1,2|", "malformed"),               # eye: 2 numbers, not 3
    (b"jawOpen-1|rightEye#1,x,2|", "malformed"),
    (b"jawOpen-1|nose#1,2,3|", "malformed"),                 # an unknown '#' item
    (b"jawOpen-1|\xff\xfe|", "malformed"),                   # not UTF-8
    (b"jawOpen-nan|", "nonfinite"),
    (b"jawOpen&inf|", "nonfinite"),
    (b"jawOpen&-Infinity|", "nonfinite"),
    (b"jawOpen-1e39|", "nonfinite"),                         # beyond float32
    (b"jawOpen-1|=head#1,2,nan,4,5,6|", "nonfinite"),
    (b"jawOpen-1|leftEye#1,inf,3|", "nonfinite"),
    (b"jawOpen-1|" + b"x" * MAX_PACKET, "oversized"),
])
def test_bad_datagrams_are_dropped_and_counted_once(data, counter):
    a = IFacialMocapAdapter()
    assert a.handle(data, 0.0) is None
    expected = dict.fromkeys(DROPS, 0)
    expected[counter] = 1
    assert outcome(a) == expected and a.counters["datagrams"] == 1
    assert a.handle(b"jawOpen-50|", 1.0) is not None  # and the next good one decodes


def test_a_full_sized_v2_datagram_decodes():
    values = {name: (i * 7) % 101 for i, name in enumerate(ARKIT_52)}
    data = ifm_frame(values, head=(1.25, -2.5, 3.75, 0.01, 0.02, 0.03), right_eye=(1, 2, 3), left_eye=(4, 5, 6),
                     extra="hapihapi-0|")
    assert 800 < len(data) < MAX_PACKET
    a = IFacialMocapAdapter()
    frame = a.handle(data, 0.0)
    assert frame is not None and np.all(np.isfinite(frame.weights))
    assert a.counters["unknown_key"] == 1


@pytest.mark.parametrize("version, tolerance", [(1, 0.005 + 1e-6), (2, 0.00005 + 1e-6)])
def test_the_runtime_encoder_round_trips(version, tolerance):
    from facepuppet.runtime.inputs.ifacialmocap import encode_ifm_frame

    weights = np.linspace(0.0, 1.0, 52)
    data = encode_ifm_frame(weights, head=(3.0, -4.0, 5.0, 0.1, 0.2, 0.3), version=version)
    assert all(ifm_name(n) in data.decode() for n in ARKIT_52)  # the app's spelling of every name
    frame = IFacialMocapAdapter().handle(data, 0.0)
    np.testing.assert_allclose(frame.weights, weights, atol=tolerance)
    np.testing.assert_allclose(frame.head_rotation, euler_to_quat(math.radians(-4), math.radians(3),
                                                                  math.radians(5)), atol=1e-6)


# One v1 datagram as a phone sent it, from the tests of korewaChino/rust-ifacialmocap (src/lib.rs, MIT licence,
# (c) Cappy Ishihara): the only public capture found; its 52 names and head/eye items are the app's own.
PUBLIC_DATAGRAM = (
    b"mouthSmile_R-0|eyeLookOut_L-0|mouthUpperUp_L-11|eyeWide_R-0|mouthClose-8|mouthPucker-4|mouthRollLower-9|"
    b"eyeBlink_R-7|eyeLookDown_L-17|cheekSquint_R-11|eyeBlink_L-7|tongueOut-0|jawRight-0|eyeLookIn_R-6|"
    b"cheekSquint_L-11|mouthDimple_L-10|mouthPress_L-4|eyeSquint_L-11|mouthRight-0|mouthShrugLower-9|eyeLookUp_R-0|"
    b"eyeLookOut_R-0|mouthPress_R-5|cheekPuff-2|jawForward-11|mouthLowerDown_L-9|mouthFrown_L-6|mouthShrugUpper-26|"
    b"browOuterUp_L-4|browInnerUp-20|mouthDimple_R-10|browDown_R-0|mouthUpperUp_R-10|mouthRollUpper-8|mouthFunnel-12|"
    b"mouthStretch_R-21|mouthFrown_R-13|eyeLookDown_R-17|jawOpen-12|jawLeft-0|browDown_L-0|mouthSmile_L-0|"
    b"noseSneer_R-18|mouthLowerDown_R-8|noseSneer_L-21|eyeWide_L-0|mouthStretch_L-21|browOuterUp_R-4|eyeLookIn_L-4|"
    b"eyeSquint_R-11|eyeLookUp_L-0|mouthLeft-1|=head#-21.488958,-6.038993,-6.6019735,-0.030653415,-0.10287084,"
    b"-0.6584072|rightEye#6.0297494,2.4403017,0.25649446|leftEye#6.034903,-1.6660284,-0.17520553|"
)


def test_the_public_datagram_gives_all_52_channels():
    a = IFacialMocapAdapter()
    frame = a.handle(PUBLIC_DATAGRAM, 0.0)
    assert frame is not None and a.counters["unknown_key"] == 0
    assert np.all(np.isfinite(frame.weights))  # every one of the 52 names is known
    w = dict(zip(frame.channels, frame.weights.tolist()))
    assert w["jawOpen"] == pytest.approx(0.12) and w["mouthShrugUpper"] == pytest.approx(0.26)
    assert w["noseSneerLeft"] == pytest.approx(0.21) and w["eyeLookDownRight"] == pytest.approx(0.17)
    np.testing.assert_allclose(frame.head_rotation, euler_to_quat(
        math.radians(-6.038993), math.radians(-21.488958), math.radians(-6.6019735)), atol=1e-6)
    np.testing.assert_allclose(frame.head_translation, (-0.030653415, -0.10287084, -0.6584072), rtol=1e-6)
    assert a.eyes["Right"] == pytest.approx((6.0297494, 2.4403017, 0.25649446))
