"""VTube Studio phone-protocol datagrams crafted from the published payload (helpers.phone_senders)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from facepuppet.runtime.inputs.kinds import INPUT_KINDS, default_port
from facepuppet.runtime.inputs.vtubestudio import MAX_MESSAGE, VTubeStudioAdapter, vts_request
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

from helpers.phone_senders import ARKIT_52, vts_frame

DROPS = ("frames", "face_lost", "malformed", "oversized", "nonfinite", "internal_error")


def outcome(adapter) -> dict:
    return {k: adapter.counters[k] for k in DROPS}


def test_registered_and_the_request_has_the_published_fields():
    assert INPUT_KINDS["vtubestudio"] is VTubeStudioAdapter and default_port("vtubestudio") == 21412
    assert VTubeStudioAdapter.phone_port == 21412
    request = json.loads(VTubeStudioAdapter.phone_request(40123))
    assert request["messageType"] == "iOSTrackingDataRequest" and request["ports"] == [40123]
    assert 0.5 <= request["time"] <= 10 and 1 <= len(request["sentBy"]) <= 32
    assert VTubeStudioAdapter.phone_every_s < request["time"]  # repeated before it runs out
    for bad in ((40123, 0.4, "x"), (40123, 11, "x"), (40123, 2, ""), (40123, 2, "x" * 33), (0, 2, "x")):
        with pytest.raises(ValueError):
            vts_request(*bad)


def test_every_blendshape_reaches_its_channel():
    values = {name: (i + 1) / 64 for i, name in enumerate(ARKIT_52)}
    frame = VTubeStudioAdapter().handle(vts_frame(values, timestamp=1_700_000_000_250), 7.0)
    assert frame is not None and frame.channels == ARKIT_NAMES and frame.t == 7.0 and frame.source == "vtubestudio"
    for name, v in values.items():
        assert frame.weights[ARKIT_NAMES.index(name)] == pytest.approx(v), name
    assert frame.t_sender == pytest.approx(1_700_000_000.25)


def test_rotation_position_and_eyes():
    a = VTubeStudioAdapter()
    frame = a.handle(vts_frame({"jawOpen": 0.5}, rotation=(10.0, -20.0, 5.0), position=(0.1, -0.2, 0.3),
                               eye_left=(0.0, 30.0, 0.0), eye_right=(15.0, 0.0, 0.0), hotkey=3), 0.0)
    expected = euler_to_quat(math.radians(-20), math.radians(10), math.radians(5))  # y yaw, x pitch, z roll
    np.testing.assert_allclose(frame.head_rotation, expected, atol=1e-6)
    np.testing.assert_allclose(frame.head_translation, (0.1, -0.2, 0.3), atol=1e-7)
    w = dict(zip(frame.channels, frame.weights.tolist()))
    assert w["eyeLookOutLeft"] == pytest.approx(1.0) and w["eyeLookDownRight"] == pytest.approx(0.5)
    assert a.hotkey == 3
    sent = a.handle(vts_frame({"eyeLookOutLeft": 0.25}, eye_left=(0.0, 30.0, 0.0)), 0.0)
    assert sent.weights[ARKIT_NAMES.index("eyeLookOutLeft")] == pytest.approx(0.25)  # what was sent wins


def test_face_not_found_is_tracking_lost_not_a_frame_of_zeros():
    a = VTubeStudioAdapter()
    assert a.handle(vts_frame({n: 0.0 for n in ARKIT_52}, found=False), 0.0) is None
    assert outcome(a) == {**dict.fromkeys(DROPS, 0), "face_lost": 1}
    assert a.handle(vts_frame({"jawOpen": 0.5}), 1.0) is not None


def test_unknown_names_are_ignored_and_counted():
    a = VTubeStudioAdapter()
    data = json.loads(vts_frame({"jawOpen": 0.5}))
    data["BlendShapes"] += [{"k": "Unknown", "v": 1.0}, {"k": "HeadYaw", "v": 0.1}]
    data["SomethingNew"] = {"a": 1}  # other keys: ignored
    frame = a.handle(json.dumps(data).encode(), 0.0)
    assert frame is not None and a.counters["unknown_key"] == 2


def _edit(change) -> bytes:
    data = json.loads(vts_frame({"jawOpen": 0.5}))
    change(data)
    return json.dumps(data).encode()


@pytest.mark.parametrize("data, counter", [
    (b"", "malformed"),
    (b"{", "malformed"),
    (b"\xff{}", "malformed"),
    (b"[1, 2]", "malformed"),
    (b'"text"', "malformed"),
    (b"{}", "malformed"),                                                  # no FaceFound
    (_edit(lambda d: d.update(FaceFound=1)), "malformed"),                 # not a bool
    (_edit(lambda d: d.update(FaceFound="true")), "malformed"),
    (_edit(lambda d: d.update(BlendShapes={"k": "JawOpen"})), "malformed"),
    (_edit(lambda d: d["BlendShapes"].append(["JawOpen", 1.0])), "malformed"),
    (_edit(lambda d: d["BlendShapes"].append({"k": 5, "v": 1.0})), "malformed"),
    (_edit(lambda d: d["BlendShapes"].append({"k": "JawOpen"})), "malformed"),   # and twice
    (_edit(lambda d: d["BlendShapes"].append({"k": "CheekPuff", "v": "1"})), "malformed"),
    (_edit(lambda d: d["BlendShapes"].append({"k": "CheekPuff", "v": True})), "malformed"),
    (_edit(lambda d: d["BlendShapes"].append({"k": "JawOpen", "v": 0.2})), "malformed"),  # duplicate
    (_edit(lambda d: d.update(Rotation=[1, 2, 3])), "malformed"),
    (_edit(lambda d: d.update(Rotation={"x": 1, "y": 2})), "malformed"),
    (_edit(lambda d: d.update(Position={"x": 1, "y": "2", "z": 3})), "malformed"),
    (_edit(lambda d: d.update(EyeLeft=5)), "malformed"),
    (_edit(lambda d: d.update(Hotkey=1.5)), "malformed"),
    (_edit(lambda d: d.update(Timestamp="now")), "malformed"),
    (_edit(lambda d: d.update(BlendShapes=[], Rotation=None)), "malformed"),  # a face but nothing to draw
    (b'{"FaceFound": true, "BlendShapes": [{"k": "JawOpen", "v": NaN}]}', "nonfinite"),
    (b'{"FaceFound": true, "BlendShapes": [{"k": "JawOpen", "v": Infinity}]}', "nonfinite"),
    (b'{"FaceFound": true, "BlendShapes": [{"k": "JawOpen", "v": 1e400}]}', "nonfinite"),
    (b'{"FaceFound": true, "BlendShapes": [{"k": "JawOpen", "v": 1e39}]}', "nonfinite"),
    (b'{"FaceFound": true, "Rotation": {"x": -Infinity, "y": 0, "z": 0}}', "nonfinite"),
    (b"[" * 100_000, "oversized"),
    (b'{"FaceFound": true, "BlendShapes": [' + b'{"k": "X", "v": 0},' * 2000 + b"]}", "oversized"),
    (b"[" * 5000 + b"]" * 5000, "malformed"),                              # deep nesting, under the size limit
])
def test_bad_datagrams_are_dropped_and_counted_once(data, counter):
    a = VTubeStudioAdapter()
    assert a.handle(data, 0.0) is None
    assert outcome(a) == {**dict.fromkeys(DROPS, 0), counter: 1} and a.counters["datagrams"] == 1
    assert a.handle(vts_frame({"jawOpen": 0.5}), 1.0) is not None  # and the next good one decodes


def test_a_real_sized_frame_is_well_under_the_limit():
    data = vts_frame({name: 0.123456789 for name in ARKIT_52}, rotation=(12.3456, -7.891, 0.5))
    assert 1500 < len(data) < MAX_MESSAGE


def test_the_runtime_encoder_round_trips():
    from facepuppet.runtime.inputs.vtubestudio import encode_vts_frame

    weights = np.linspace(0.0, 1.0, 52)
    data = encode_vts_frame(weights, rotation=(3.0, -4.0, 5.0), timestamp_ms=1500)
    assert [e["k"] for e in json.loads(data)["BlendShapes"]] == [n[0].upper() + n[1:] for n in ARKIT_52]
    frame = VTubeStudioAdapter().handle(data, 0.0)
    np.testing.assert_allclose(frame.weights, weights, atol=1e-7)
    assert frame.t_sender == 1.5
