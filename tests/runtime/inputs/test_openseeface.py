"""OpenSeeFace input: crafted records from the independent sender (helpers/openseeface_sender.py).

Expected weights are worked out by hand from the mapping table in PROTOCOLS.md §9 (not by calling the
decoder's mapping), poses from the reference receiver's conversion written out here.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from facepuppet.runtime.inputs.kinds import default_port, make_adapter
from facepuppet.runtime.inputs.openseeface import MAX_FACES, RECORD_SIZE, OpenSeeFaceAdapter, encode_record
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.openseeface_sender import FEATURE_ORDER, REST_QUATERNION, SIZE, float_offsets, osf_record
from helpers.osc_helpers import counts

IDX = {n: i for i, n in enumerate(ARKIT_NAMES)}
MAPPED = {"eyeBlinkLeft", "eyeBlinkRight", "eyeWideLeft", "eyeWideRight", "browInnerUp", "browOuterUpLeft",
          "browOuterUpRight", "browDownLeft", "browDownRight", "jawOpen", "mouthStretchLeft", "mouthStretchRight",
          "mouthPucker", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight"}


def frame_of(data: bytes, face_id=None):
    adapter = OpenSeeFaceAdapter(face_id=face_id)
    return adapter.handle(data, 5.0), adapter


def nonzero(frame) -> dict[str, float]:
    return {n: round(float(frame.weights[IDX[n]]), 5) for n in MAPPED if frame.weights[IDX[n]] != 0}


def test_published_sizes_and_default_port():
    assert SIZE == RECORD_SIZE == 1785
    assert default_port("openseeface") == 11573 and make_adapter("openseeface").face_id is None


GAZE = {f"eyeLook{d}{s}" for d in ("In", "Out", "Up", "Down") for s in ("Left", "Right")}


def eyes_points(right_forward=(0.0, 0.0, 1.0), left_forward=(0.0, 0.0, 1.0)) -> list:
    """70 3D points whose eyes look along the given directions (our axes): centre = pupil + forward (the
    reference receiver's eye forward is centre - pupil of the raw points)."""
    points = [(0.01 * i, -0.02 * i, 0.03) for i in range(70)]
    points[66], points[67] = (-0.03, 0.0, 0.0), (0.03, 0.0, 0.0)
    points[68] = tuple(p + 0.012 * f for p, f in zip(points[66], right_forward))
    points[69] = tuple(p + 0.012 * f for p, f in zip(points[67], left_forward))
    return points


def test_a_neutral_record_is_all_zero_mapped_channels_nan_elsewhere_and_rest_pose():
    frame, adapter = frame_of(osf_record(time=1234.5, points=eyes_points()))
    counts(adapter, datagrams=1, frames=1)
    assert frame.channels == ARKIT_NAMES and frame.t == 5.0 and frame.t_sender == 1234.5
    for name in ARKIT_NAMES:
        value = float(frame.weights[IDX[name]])
        assert (value == 0.0) if name in MAPPED | GAZE else math.isnan(value), name
    np.testing.assert_allclose(frame.head_rotation, [0, 0, 0, 1], atol=1e-6)
    assert frame.head_translation is None
    np.testing.assert_allclose(adapter.translation, [0.5, -0.25, 6.0])
    assert adapter.camera == (640.0, 360.0)


# each feature alone -> the channels it drives (values by hand from the table, ramp(x, a, b) = (x-a)/(b-a))
FEATURE_CASES = [
    ("eye_l", 0.75, {"eyeWideLeft": 0.35}),                       # 0.7 * (0.75-0.5)/0.5
    ("eye_r", 1.0, {"eyeWideRight": 0.7}),
    ("eye_l", -0.9, {}),                                           # a closing eye is the openness field's job
    ("eyebrow_steepness_l", -0.3, {"browOuterUpLeft": 0.3}),
    ("eyebrow_steepness_r", -0.6, {"browOuterUpRight": 0.6}),
    ("eyebrow_steepness_r", 0.6, {}),
    ("eyebrow_updown_l", 0.5, {"browInnerUp": 0.2}),               # 0.8 * mean(0.5, 0)
    ("eyebrow_updown_r", -0.25, {"browDownRight": 0.25}),
    ("eyebrow_updown_l", -1.0, {"browDownLeft": 1.0}),
    ("eyebrow_quirk_l", 0.9, {}),
    ("eyebrow_quirk_r", -0.9, {}),
    ("mouth_corner_updown_l", 0.65, {"mouthSmileLeft": 0.5}),     # (0.65-0.3)/0.7
    ("mouth_corner_updown_r", -0.65, {"mouthFrownRight": 0.5}),
    ("mouth_corner_updown_l", 0.2, {}),                           # inside the dead zone
    ("mouth_corner_inout_l", 0.8, {}),
    ("mouth_corner_inout_r", -0.8, {}),
    ("mouth_open", 0.6, {"jawOpen": 0.6}),
    ("mouth_open", -0.4, {}),
    ("mouth_wide", 0.65, {"mouthStretchLeft": 0.5, "mouthStretchRight": 0.5}),
    ("mouth_wide", -1.0, {"mouthPucker": 1.0}),
]


@pytest.mark.parametrize("name, value, expected", FEATURE_CASES, ids=[f"{n}={v}" for n, v, _ in FEATURE_CASES])
def test_each_feature_drives_only_its_channels(name, value, expected):
    frame, _ = frame_of(osf_record(features={name: value}))
    assert nonzero(frame) == pytest.approx(expected, abs=1e-5)


def test_every_feature_position_is_read_at_its_published_offset():
    """A distinct value in each of the 14 slots, read back from the raw record field by field."""
    values = {n: 0.05 * (i + 1) for i, n in enumerate(FEATURE_ORDER)}
    data = osf_record(features=values)
    for i, name in enumerate(FEATURE_ORDER):
        assert struct.unpack_from("<f", data, 1729 + 4 * i)[0] == pytest.approx(values[name])
    frame, _ = frame_of(data)
    # mouth_open is slot 12 (0.65), mouth_wide slot 13 (0.7): jawOpen 0.65, stretch (0.7-0.3)/0.7
    assert float(frame.weights[IDX["jawOpen"]]) == pytest.approx(0.65)
    assert float(frame.weights[IDX["mouthStretchLeft"]]) == pytest.approx(0.4 / 0.7)
    # eye_l slot 0 (0.05), eye_r slot 1 (0.1): below 0.5, no wide; steepness_l slot 2 positive: no outer up
    assert float(frame.weights[IDX["eyeWideLeft"]]) == 0.0 and float(frame.weights[IDX["browOuterUpLeft"]]) == 0.0
    # updown_l slot 3 (0.2), updown_r slot 6 (0.35): inner up 0.8 * 0.275
    assert float(frame.weights[IDX["browInnerUp"]]) == pytest.approx(0.22)
    # corner_updown_l slot 8 (0.45) -> smile (0.15/0.7); corner_updown_r slot 10 (0.55) -> (0.25/0.7)
    assert float(frame.weights[IDX["mouthSmileLeft"]]) == pytest.approx(0.15 / 0.7)
    assert float(frame.weights[IDX["mouthSmileRight"]]) == pytest.approx(0.25 / 0.7)


@pytest.mark.parametrize("right_open, left_open, blink_r, blink_l", [
    (1.0, 1.0, 0.0, 0.0), (0.75, 1.0, 0.0, 0.0),        # closure 0.25: inside the dead zone
    (0.5, 1.0, 0.2 / (2 / 3 - 0.3), 0.0),               # closure 0.5
    (1.0, 0.2, 0.0, 1.0), (0.0, 0.0, 1.0, 1.0),
])
def test_eye_openness_fields_drive_the_blinks_on_their_own_side(right_open, left_open, blink_r, blink_l):
    frame, _ = frame_of(osf_record(right_open=right_open, left_open=left_open))
    assert float(frame.weights[IDX["eyeBlinkRight"]]) == pytest.approx(blink_r, abs=1e-6)
    assert float(frame.weights[IDX["eyeBlinkLeft"]]) == pytest.approx(blink_l, abs=1e-6)


def test_out_of_range_values_are_clipped_not_dropped():
    frame, adapter = frame_of(osf_record(right_open=7.0, left_open=-3.0,
                                         features={"mouth_open": 40.0, "mouth_wide": -9.0, "eye_l": 5.0}))
    counts(adapter, datagrams=1, frames=1)
    assert nonzero(frame) == {"eyeBlinkLeft": 1.0, "jawOpen": 1.0, "mouthPucker": 1.0, "eyeWideLeft": 0.7}


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def raw_from_unity(unity_rel):
    """The raw quaternion whose reference-receiver reading is ``unity_rel`` after its rest pose:
    the receiver computes C = (-qy, -qx, qz, qw) and the pose C * C0^-1, C0 a 90° roll about z."""
    c = _qmul(unity_rel, REST_QUATERNION)
    cx, cy, cz, cw = c
    return (-cy, -cx, cz, cw)


def _rotate(q, v):
    x, y, z, w = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return r @ np.asarray(v, float)


@pytest.mark.parametrize("axis, expect", [
    # Unity: +y turns the +z-facing head to its own right (+x in Unity, -x in ours: x is the character's left)
    ((0, 1, 0), lambda fwd, up: fwd[0] < -0.3 and abs(up[1] - 1) < 1e-6),
    # Unity: +x tips the face (+z) downwards (-y): a nod down, same in ours
    ((1, 0, 0), lambda fwd, up: fwd[1] < -0.3 and abs(fwd[0]) < 1e-6),
    # Unity: +z rolls the top of the head towards -x (Unity's left of the avatar = the avatar's left):
    # in ours the up vector goes towards +x (the character's left)
    ((0, 0, 1), lambda fwd, up: up[0] > 0.3 and abs(fwd[2] - 1) < 1e-6),
])
def test_head_rotation_follows_the_reference_receiver_into_our_axes(axis, expect):
    half = math.radians(30) / 2
    unity_rel = (axis[0] * math.sin(half), axis[1] * math.sin(half), axis[2] * math.sin(half), math.cos(half))
    frame, _ = frame_of(osf_record(quaternion=raw_from_unity(unity_rel)))
    q = frame.head_rotation.astype(float)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-6)
    fwd, up = _rotate(q, (0, 0, 1)), _rotate(q, (0, 1, 0))
    assert expect(fwd, up), (q, fwd, up)
    # exactly the VMC mirror of the Unity rotation: (x, y, z, w) -> (x, -y, -z, w)
    mirrored = (unity_rel[0], -unity_rel[1], -unity_rel[2], unity_rel[3])
    np.testing.assert_allclose(q, mirrored, atol=1e-6)


def test_a_scaled_quaternion_is_normalised():
    frame, _ = frame_of(osf_record(quaternion=tuple(3.0 * c for c in REST_QUATERNION)))
    np.testing.assert_allclose(frame.head_rotation, [0, 0, 0, 1], atol=1e-6)


def test_a_failed_3d_fit_gives_weights_without_a_pose():
    frame, adapter = frame_of(osf_record(fit=0, quaternion=(0, 0, 0, 0), features={"mouth_open": 0.5}))
    counts(adapter, datagrams=1, frames=1, no_fit=1)
    assert frame.head_rotation is None and float(frame.weights[IDX["jawOpen"]]) == 0.5


def test_the_face_is_picked_by_id_default_the_first():
    data = osf_record(face_id=3, features={"mouth_open": 0.2}) + osf_record(face_id=7, features={"mouth_open": 0.8})
    first, adapter = frame_of(data)
    assert float(first.weights[IDX["jawOpen"]]) == pytest.approx(0.2) and adapter.faces_seen == 2
    seven, _ = frame_of(data, face_id=7)
    assert float(seven.weights[IDX["jawOpen"]]) == pytest.approx(0.8)
    none, adapter = frame_of(data, face_id=5)
    assert none is None
    counts(adapter, datagrams=1, other_face=1)


def test_a_bad_record_not_picked_does_not_spoil_the_picked_one():
    bad = bytearray(osf_record(face_id=1))
    struct.pack_into("<f", bad, 1729, math.nan)
    frame, adapter = frame_of(osf_record(face_id=2, features={"mouth_open": 0.4}) + bytes(bad), face_id=2)
    counts(adapter, datagrams=1, frames=1)
    assert float(frame.weights[IDX["jawOpen"]]) == pytest.approx(0.4)


@pytest.mark.parametrize("length", [0, 1, 12, RECORD_SIZE - 1, RECORD_SIZE + 1, 2 * RECORD_SIZE - 1,
                                    2 * RECORD_SIZE + 7])
def test_a_length_that_is_not_a_whole_number_of_records_is_malformed(length):
    data = (osf_record() * 3)[:length]
    frame, adapter = frame_of(data)
    assert frame is None
    counts(adapter, datagrams=1, malformed=1)


def test_every_truncation_of_a_record_is_malformed():
    data = osf_record()
    adapter = OpenSeeFaceAdapter()
    for n in range(len(data)):
        assert adapter.handle(data[:n], 0.0) is None
    counts(adapter, datagrams=len(data), malformed=len(data))


def test_oversized_datagrams_are_counted_and_the_largest_legal_one_decodes():
    adapter = OpenSeeFaceAdapter()
    assert adapter.handle(osf_record() * MAX_FACES, 0.0) is not None
    assert adapter.handle(osf_record() * (MAX_FACES + 1), 0.0) is None
    assert adapter.handle(b"\0" * 70_000, 0.0) is None
    counts(adapter, datagrams=3, frames=1, oversized=2)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_nonfinite_value_in_any_field_rejects_the_record(bad):
    adapter = OpenSeeFaceAdapter()
    offsets = float_offsets()
    for at in offsets:
        data = bytearray(osf_record())
        struct.pack_into("<f", data, at, bad)
        assert adapter.handle(bytes(data), 0.0) is None, at
    assert adapter.handle(osf_record(time=bad), 0.0) is None
    counts(adapter, datagrams=len(offsets) + 1, nonfinite=len(offsets) + 1)


@pytest.mark.parametrize("fit", [2, 7, 255])
def test_a_fit_flag_that_is_not_0_or_1_is_malformed(fit):
    frame, adapter = frame_of(osf_record(fit=fit))
    assert frame is None
    counts(adapter, datagrams=1, malformed=1)


def test_a_fitted_zero_quaternion_is_malformed():
    frame, adapter = frame_of(osf_record(quaternion=(0.0, 0.0, 0.0, 0.0)))
    assert frame is None
    counts(adapter, datagrams=1, malformed=1)


def test_other_protocols_are_refused():
    """Wrong types: an OSC datagram, JSON, a Live Link Face packet; none is a whole number of records."""
    from facepuppet.runtime.inputs.livelinkface import encode_llf_packet

    from helpers.osc_helpers import osc

    adapter = OpenSeeFaceAdapter()
    for data in (osc("/VMC/Ext/Blend/Apply"), b'{"messageType": "iOSTrackingDataRequest"}',
                 encode_llf_packet([0.0] * 52)):
        assert adapter.handle(data, 0.0) is None
    counts(adapter, datagrams=3, malformed=3)


def test_encode_record_matches_the_independent_sender_byte_for_byte():
    feats = {n: 0.01 * (i - 7) for i, n in enumerate(FEATURE_ORDER)}
    q = (0.1, 0.2, 0.3, 0.9)
    ours = encode_record(time=99.25, face_id=4, camera=(1280.0, 720.0), right_open=0.3, left_open=0.6, fit=1,
                         fit_error=3.5, quaternion=q, euler=(170.0, 5.0, 80.0), translation=(1.0, 2.0, 3.0),
                         features=[feats[n] for n in FEATURE_ORDER],
                         confidence=[0.9] * 68, landmarks=[(100.0 + i, 200.0 + i) for i in range(68)],
                         points=[(0.01 * i, -0.02 * i, 0.03) for i in range(70)])
    theirs = osf_record(time=99.25, face_id=4, width=1280.0, height=720.0, right_open=0.3, left_open=0.6,
                        fit_error=3.5, quaternion=q, euler=(170.0, 5.0, 80.0), translation=(1.0, 2.0, 3.0),
                        features=feats)
    assert ours == theirs


def test_the_adapter_pickles_with_its_face_id():
    import pickle

    adapter = pickle.loads(pickle.dumps(OpenSeeFaceAdapter(face_id=9)))
    assert adapter.face_id == 9 and adapter.handle(osf_record(face_id=9), 0.0) is not None


def test_the_eyes_3d_points_give_the_gaze_as_eye_look_weights():
    yaw = (math.sin(math.radians(20)), 0.0, math.cos(math.radians(20)))  # 20 deg toward the person's own left
    down = (0.0, -math.sin(math.radians(15)), math.cos(math.radians(15)))  # 15 deg down
    frame, _ = frame_of(osf_record(points=eyes_points(right_forward=yaw, left_forward=down)))
    w = {n: float(frame.weights[IDX[n]]) for n in GAZE}
    assert w["eyeLookInRight"] == pytest.approx(20 / 30, abs=1e-4)  # the right eye turns to the nose
    assert w["eyeLookDownLeft"] == pytest.approx(15 / 30, abs=1e-4)
    assert sum(w.values()) == pytest.approx(20 / 30 + 15 / 30, abs=1e-4)
    no_fit, _ = frame_of(osf_record(fit=0, points=eyes_points(right_forward=yaw)))
    assert all(math.isnan(no_fit.weights[IDX[n]]) for n in GAZE)  # no fit: no gaze
