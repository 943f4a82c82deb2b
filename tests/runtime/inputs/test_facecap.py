"""Face Cap adapter fed with crafted datagrams: index order, head pose, eyes, frame rule, counters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.inputs.facecap import FACECAP_ORDER, FaceCapAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import bundle, counts, msg

INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}


def frame(*messages) -> bytes:
    """One Face Cap frame in one bundle: ``messages``, then ``/HT`` (Face Cap sends it once a frame)."""
    return bundle(*messages, msg("/HT", 0.0, 0.0, 1.0))


def test_index_24_is_jaw_open_in_face_cap_order():
    a = FaceCapAdapter()
    f = a.handle(frame(msg("/W", 24, 0.5)), 1.0)
    assert f.weights[INDEX["jawOpen"]] == 0.5 and f.source == "facecap"
    assert np.isnan(np.delete(f.weights, INDEX["jawOpen"])).all()
    counts(a, datagrams=1, frames=1)


def test_face_cap_order_is_a_permutation_of_arkit_and_not_arkit_order():
    assert sorted(FACECAP_ORDER) == sorted(ARKIT_NAMES) and FACECAP_ORDER != ARKIT_NAMES
    spot = {0: "browInnerUp", 13: "eyeBlinkLeft", 19: "cheekPuff", 36: "mouthClose", 51: "tongueOut"}
    assert {i: FACECAP_ORDER[i] for i in spot} == spot
    f = FaceCapAdapter().handle(frame(*(msg("/W", i, i / 100) for i in range(52))), 0.0)
    for i, name in enumerate(FACECAP_ORDER):
        assert f.weights[INDEX[name]] == pytest.approx(i / 100)


def test_head_rotation_degrees_quaternion_and_translation():
    a = FaceCapAdapter()
    f = a.handle(bundle(msg("/HR", 0.0, 90.0, 0.0), msg("/HT", 1.0, 2.0, 3.0)), 0.0)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(f.head_rotation, [0, s, 0, s], atol=1e-6)  # 90° about +y
    np.testing.assert_allclose(f.head_translation, [1, 2, 3])
    # no /HT this time: the bundle holding all 52 indices completes the frame
    g = a.handle(bundle(msg("/HR", 10.0, 0.0, 0.0), msg("/HRQ", 0.0, 0.0, 2.0, 2.0),
                        *(msg("/W", i, 0.5) for i in range(52))), 1.0)
    np.testing.assert_allclose(g.head_rotation, [0, 0, s, s], atol=1e-6)  # HRQ wins, normalised
    np.testing.assert_allclose(g.head_translation, [1, 2, 3])  # persists
    counts(a, datagrams=2, frames=2)


def test_eye_rotations_drive_eye_look_and_w_values_win():
    a = FaceCapAdapter()
    f = a.handle(frame(msg("/ELR", 15.0, 0.0), msg("/ERR", 0.0, 15.0)), 0.0)
    assert f.weights[INDEX["eyeLookDownLeft"]] == pytest.approx(0.5) and f.weights[INDEX["eyeLookUpLeft"]] == 0
    assert f.weights[INDEX["eyeLookInRight"]] == pytest.approx(0.5) and f.weights[INDEX["eyeLookOutRight"]] == 0
    g = a.handle(frame(msg("/ELR", -90.0, 0.0), msg("/W", 7, 0.25)), 1.0)  # index 7: eyeLookDownLeft
    assert g.weights[INDEX["eyeLookDownLeft"]] == 0.25 and g.weights[INDEX["eyeLookUpLeft"]] == 1.0  # clamped


def test_unbundled_frames_end_on_ht_or_on_a_repeated_index():
    a = FaceCapAdapter()
    assert a.handle(msg("/W", 24, 0.5).dgram, 1.00) is None
    assert a.handle(msg("/W", 37, 0.2).dgram, 1.01) is None
    f = a.handle(msg("/HT", 0.0, 0.0, 1.0).dgram, 1.02)
    assert f.weights[INDEX["jawOpen"]] == 0.5 and f.weights[INDEX["mouthSmileLeft"]] == pytest.approx(0.2)
    assert a.handle(msg("/W", 24, 0.6).dgram, 1.03) is None
    g = a.handle(msg("/W", 24, 0.7).dgram, 1.04)  # index 24 again: the frame holding 0.6 is complete
    assert g.weights[INDEX["jawOpen"]] == pytest.approx(0.6) and g.t == 1.04
    h = a.handle(msg("/HT", 0.0, 0.0, 1.0).dgram, 1.05)
    assert h.weights[INDEX["jawOpen"]] == pytest.approx(0.7)
    counts(a, datagrams=6, frames=3)


def test_at_most_one_frame_per_receive_time():
    a = FaceCapAdapter()
    assert a.handle(frame(msg("/W", 24, 0.5)), 2.0) is not None
    assert a.handle(frame(msg("/W", 25, 0.3)), 2.0) is None  # same time: carried to the next frame
    f = a.handle(frame(msg("/W", 24, 0.1)), 2.1)
    assert f.weights[INDEX["jawForward"]] == pytest.approx(0.3) and f.weights[INDEX["jawOpen"]] == pytest.approx(0.1)


@pytest.mark.parametrize("message", [
    msg("/W", 24.0, 0.5),       # index is a float
    msg("/W", "24", 0.5),
    msg("/W", 24),              # value missing
    msg("/W", 52, 0.5),         # index out of range
    msg("/W", -1, 0.5),
    msg("/W", 24, "half"),
    msg("/HR", 0.0, 0.0),       # too few
    msg("/HT", "x", 0.0, 0.0),
    msg("/HRQ", 0.0, 0.0, 0.0, 0.0),  # not a rotation
    msg("/ELR", 1.0),
    msg("/ERR"),
])
def test_wrong_types_and_counts_are_malformed(message):
    a = FaceCapAdapter()
    assert a.handle(bundle(message), 0.0) is None
    f = a.handle(frame(msg("/W", 25, 0.5), msg("/W", 24, 0.25, "extra", 3)), 1.0)  # extras ignored
    assert f.weights[INDEX["jawOpen"]] == 0.25 and f.weights[INDEX["jawForward"]] == 0.5
    counts(a, datagrams=2, frames=1, malformed=1)


@pytest.mark.parametrize("message", [msg("/W", 24, math.nan), msg("/HT", math.inf, 0.0, 0.0),
                                     msg("/HR", 0.0, -math.inf, 0.0), msg("/ELR", math.nan, 0.0)])
def test_nonfinite_value_rejects_its_frame(message):
    a = FaceCapAdapter()
    bad = bundle(msg("/W", 25, 0.5), message) if message.address == "/HT" else frame(msg("/W", 25, 0.5), message)
    assert a.handle(bad, 0.0) is None  # a whole frame (it ends on /HT) holding the bad value
    f = a.handle(frame(msg("/W", 24, 0.5)), 1.0)
    assert np.isnan(f.weights[INDEX["jawForward"]]) and f.head_rotation is None
    np.testing.assert_array_equal(f.head_translation, [0.0, 0.0, 1.0])
    counts(a, datagrams=2, frames=1, nonfinite=1)


def test_unknown_addresses_truncated_and_empty_datagrams():
    a = FaceCapAdapter()
    assert a.handle(bundle(msg("/Blend", 1, 0.5), msg("/w", 24, 0.5)), 0.0) is None
    assert a.handle(b"", 0.1) is None
    data = msg("/W", 24, 0.5).dgram
    for n in range(1, len(data)):
        assert a.handle(data[:n], 0.2 + n) is None
    counts(a, datagrams=len(data) + 1, unknown_address=2, malformed=len(data))


def test_a_frame_split_over_two_bundles_is_emitted_once_whole():
    """Issue 12 §5: each bundle was a frame, so the second half's frame had the first half's channels NaN
    (drawn as 0)."""
    a = FaceCapAdapter()
    for k in range(3):
        values = [(i + k) % 52 / 51 for i in range(52)]
        first = bundle(msg("/HR", 0.0, 5.0, 0.0), *(msg("/W", i, values[i]) for i in range(26)))
        second = bundle(*(msg("/W", i, values[i]) for i in range(26, 52)), msg("/HT", 0.0, 0.0, float(k)))
        assert a.handle(first, 1.0 + k) is None
        f = a.handle(second, 1.01 + k)
        for i, name in enumerate(FACECAP_ORDER):
            assert f.weights[INDEX[name]] == pytest.approx(values[i], abs=1e-6), name
        assert f.head_translation[2] == k and f.head_rotation is not None
    counts(a, datagrams=6, frames=3)


def test_two_frames_in_one_bundle_end_on_ht_and_the_newest_wins():
    a = FaceCapAdapter()
    f = a.handle(bundle(msg("/W", 24, 0.2), msg("/HT", 0.0, 0.0, 1.0), msg("/W", 24, 0.4), msg("/W", 25, 0.1)), 1.0)
    assert f.weights[INDEX["jawOpen"]] == pytest.approx(0.2)  # the second frame is not complete yet
    g = a.handle(bundle(msg("/W", 26, 0.3), msg("/HT", 0.0, 0.0, 2.0)), 2.0)
    assert g.weights[INDEX["jawOpen"]] == pytest.approx(0.4) and g.weights[INDEX["jawLeft"]] == pytest.approx(0.3)
    counts(a, datagrams=2, frames=2)


@pytest.mark.parametrize("receiver", ["thread", "process"])
def test_both_receivers_give_whole_frames_from_split_bundles(receiver):
    """The same over real UDP: each receiver decodes with its own adapter (the process one in the child)."""
    import socket

    from facepuppet.runtime.inputs.udp import UdpSource
    from facepuppet.runtime.inputs.udp_process import UdpProcessSource

    from helpers.udp_helpers import wait_for

    kind = UdpProcessSource if receiver == "process" else UdpSource
    with kind(FaceCapAdapter(), port=0) as source, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for k in range(4):
            values = [(i * 7 + k) % 52 / 51 for i in range(52)]
            sender.sendto(bundle(*(msg("/W", i, values[i]) for i in range(30))), source.address)
            sender.sendto(bundle(*(msg("/W", i, values[i]) for i in range(30, 52)), msg("/HT", 0.0, 0.0, 1.0)),
                          source.address)
            wait_for(lambda n=2 * (k + 1): source.counters["datagrams"] == n, "both halves")
            f, _ = source.latest()
            for i, name in enumerate(FACECAP_ORDER):
                assert f.weights[INDEX[name]] == pytest.approx(values[i], abs=1e-6), (k, name)
        assert source.counters["frames"] == 4
