"""Live Link Face UDP adapter: version-6 packets built by hand (PROTOCOLS.md §5) and damaged ones."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from facepuppet.runtime.inputs.livelinkface import MAX_PACKET, LiveLinkFaceAdapter, encode_llf_packet
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

from helpers.osc_helpers import counts

UUID = b"$" + b"A1B2C3D4-0000-1111-2222-333344445555"[:36]


def packet(values, name=b"Actor", version=6, count=61, number=120, sub=0.5, fps=60, den=1, uuid=UUID):
    """A packet laid out field by field as in §5, independent of encode_llf_packet."""
    return (struct.pack("<i", version) + uuid + struct.pack(">i", len(name)) + name
            + struct.pack(">ifii", number, sub, fps, den) + struct.pack(">B", count)
            + struct.pack(f">{len(values)}f", *values))


def values61(**named):
    v = [0.0] * 61
    for k, x in named.items():
        v[ARKIT_NAMES.index(k) if k in ARKIT_NAMES else 52 + ("yaw", "pitch", "roll").index(k)] = x
    return v


def test_jaw_open_at_arkit_index_17_and_head_rotation():
    assert ARKIT_NAMES[17] == "jawOpen" and len(UUID) == 37
    a = LiveLinkFaceAdapter()
    f = a.handle(packet(values61(jawOpen=0.75, eyeBlinkRight=0.5, yaw=0.3, pitch=-0.1, roll=0.05)), 4.0)
    assert f.channels == ARKIT_NAMES and f.t == 4.0 and f.source == "livelinkface"
    assert f.weights[17] == 0.75 and f.weights[7] == 0.5 and f.weights[0] == 0
    np.testing.assert_allclose(f.head_rotation, euler_to_quat(0.3, -0.1, 0.05), atol=1e-6)
    assert f.number == 120 and f.t_sender == pytest.approx(120.5 / 60)
    assert a.device_name == "Actor"
    counts(a, datagrams=1, frames=1)


def test_encode_llf_packet_matches_the_hand_layout():
    v = values61(jawOpen=0.25, yaw=0.1)
    built = encode_llf_packet(v[:52], head=v[52:55], eyes=v[55:], number=120, sub_frame=0.5,
                          name="Actor", device_id=UUID.decode())
    assert built == packet(v)
    assert struct.unpack_from(">i", built, 41)[0] == 5 and built[45 + 5 + 16] == 61  # §5 offsets


def test_fps_zero_gives_nan_sender_time_and_utf8_names_decode():
    a = LiveLinkFaceAdapter()
    f = a.handle(packet(values61(), name="iPhone de Zoé".encode(), fps=0), 0.0)
    assert math.isnan(f.t_sender) and a.device_name == "iPhone de Zoé"


@pytest.mark.parametrize("data", [
    b"",
    packet(values61(), version=5),
    packet(values61(), version=0x06000000),          # version big-endian by mistake
    packet(values61(), count=52),                   # count field disagrees with the layout
    packet(values61())[:-1],                        # truncated
    packet(values61()) + b"\x00",                   # trailing byte
    packet(values61(), uuid=b"#" + UUID[1:]),       # device id must start with "$"
    packet(values61())[:41] + struct.pack(">i", -3) + packet(values61())[45:],   # negative name length
    packet(values61())[:41] + struct.pack(">i", 999) + packet(values61())[45:],  # name past the end
    packet(values61()[:60], count=60),
])
def test_damaged_packets_are_malformed(data):
    a = LiveLinkFaceAdapter()
    assert a.handle(data, 0.0) is None
    counts(a, datagrams=1, malformed=1)


def test_every_truncation_is_malformed():
    a = LiveLinkFaceAdapter()
    data = packet(values61(jawOpen=1.0))
    for n in range(len(data)):
        assert a.handle(data[:n], float(n)) is None
    counts(a, datagrams=len(data), malformed=len(data))


@pytest.mark.parametrize("index", [17, 53, 60])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_nonfinite_values_reject_the_packet(index, bad):
    a = LiveLinkFaceAdapter()
    v = values61()
    v[index] = bad
    assert a.handle(packet(v), 0.0) is None
    counts(a, datagrams=1, nonfinite=1)


def test_oversized_packet():
    a = LiveLinkFaceAdapter()
    assert a.handle(packet(values61(), name=b"x" * MAX_PACKET), 0.0) is None
    counts(a, datagrams=1, oversized=1)


def test_encode_llf_packet_refuses_wrong_sizes():
    with pytest.raises(ValueError, match="expected 52 weights"):
        encode_llf_packet([0.0] * 51)
