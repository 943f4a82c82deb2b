"""VMC receive details (issue 16 item 6): /VMC/Ext/Cam, the head from /VMC/Ext/Bone/Pos "Head" in our axes,
/VMC/Ext/Tra/Pos and /VMC/Ext/Hmd/Pos trackers, while blend values keep working.

The datagrams are packed here by hand from the OSC 1.0 rules (strings NUL-padded to 4 bytes, big-endian
int32/float32, ``#bundle`` elements size-prefixed), not with python-osc.
"""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from facepuppet.runtime.inputs.vmc import MAX_TRACKERS, VmcAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

from helpers.osc_helpers import counts

JAW = ARKIT_NAMES.index("jawOpen")


def _pad(b: bytes) -> bytes:
    b += b"\0"
    return b + b"\0" * (-len(b) % 4)


def osc(address: str, *args) -> bytes:
    """One OSC message: str -> s, int -> i, float -> f (big-endian)."""
    tags, data = ",", b""
    for a in args:
        if isinstance(a, str):
            tags, data = tags + "s", data + _pad(a.encode())
        elif isinstance(a, int):
            tags, data = tags + "i", data + struct.pack(">i", a)
        else:
            tags, data = tags + "f", data + struct.pack(">f", a)
    return _pad(address.encode()) + _pad(tags.encode()) + data


def bundle(*messages: bytes) -> bytes:
    return b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(m)) + m for m in messages)


def jaw(value: float) -> bytes:
    return bundle(osc("/VMC/Ext/Blend/Val", "JawOpen", value), osc("/VMC/Ext/Blend/Apply"))


def unity_quat(axis, degrees):
    h = math.radians(degrees) / 2
    return tuple(c * math.sin(h) for c in axis) + (math.cos(h),)


def rotate(q, v):
    x, y, z, w = (float(c) for c in q)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return r @ np.asarray(v, float)


# Unity (left-handed, avatar facing +z, x to its right): +y turns the face towards +x (its right);
# +x tips the face down; +z tilts the top of the head towards -x (its left). In ours x is the character's
# left, so: a turn to its right moves the face to -x, a tilt to its left moves the top to +x.
@pytest.mark.parametrize("axis, check", [
    ((0, 1, 0), lambda fwd, up: fwd[0] < -0.4 and abs(up[1] - 1) < 1e-6),
    ((1, 0, 0), lambda fwd, up: fwd[1] < -0.4 and abs(fwd[0]) < 1e-6),
    ((0, 0, 1), lambda fwd, up: up[0] > 0.4 and abs(fwd[2] - 1) < 1e-6),
])
def test_head_bone_rotation_in_our_axes_and_its_position_left_alone(axis, check):
    a = VmcAdapter()
    q = unity_quat(axis, 40)
    a.handle(osc("/VMC/Ext/Bone/Pos", "Head", 0.03, 0.12, -0.01, *q), 0.0)
    f = a.handle(jaw(0.5), 0.1)
    assert f.weights[JAW] == pytest.approx(0.5) and a.head_source == "bone"
    fwd, up = rotate(f.head_rotation, (0, 0, 1)), rotate(f.head_rotation, (0, 1, 0))
    assert check(fwd, up), (f.head_rotation, fwd, up)
    np.testing.assert_allclose(f.head_rotation, (q[0], -q[1], -q[2], q[3]), atol=1e-6)
    assert f.head_translation is None  # the bone's local offset from its parent is no head motion
    counts(a, datagrams=2, frames=1)


def test_camera_is_kept_in_our_axes_and_drives_nothing():
    a = VmcAdapter()
    q = unity_quat((0, 1, 0), 180)
    assert a.handle(osc("/VMC/Ext/Cam", "Camera", 0.5, 1.4, 2.0, *q, 35.0), 0.0) is None
    assert a.camera["name"] == "Camera" and a.camera["fov"] == pytest.approx(35.0)
    np.testing.assert_allclose(a.camera["position"], (-0.5, 1.4, 2.0), atol=1e-6)
    np.testing.assert_allclose(a.camera["rotation"], (q[0], -q[1], -q[2], q[3]), atol=1e-6)
    f = a.handle(jaw(0.25), 0.1)
    assert f.head_rotation is None and f.weights[JAW] == pytest.approx(0.25)
    counts(a, datagrams=2, frames=1)


@pytest.mark.parametrize("message", [
    osc("/VMC/Ext/Cam", "Camera", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),            # no fov
    osc("/VMC/Ext/Cam", 7, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 40.0),             # name not a string
    osc("/VMC/Ext/Cam", "Camera", 0.0, "x", 0.0, 0.0, 0.0, 0.0, 1.0, 40.0),      # a string for a float
    osc("/VMC/Ext/Cam", "Camera", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 40.0),      # zero quaternion
    osc("/VMC/Ext/Tra/Pos", "LHR-1", 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),               # 6 floats
    osc("/VMC/Ext/Tra/Pos", 3, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    osc("/VMC/Ext/Hmd/Pos", "HMD", 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0),           # zero quaternion
    osc("/VMC/Ext/Bone/Pos", "Neck", 0.0, 1.0),                                    # other bone, too few
])
def test_wrong_types_and_too_few_arguments_are_malformed_and_blend_values_keep_working(message):
    a = VmcAdapter()
    assert a.handle(message, 0.0) is None
    f = a.handle(jaw(0.75), 0.1)
    assert f.weights[JAW] == pytest.approx(0.75) and f.head_rotation is None and a.camera is None
    assert a.trackers == {}
    counts(a, datagrams=2, frames=1, malformed=1)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("address, n", [("/VMC/Ext/Cam", 8), ("/VMC/Ext/Tra/Pos", 7), ("/VMC/Ext/Hmd/Pos", 7)])
def test_nonfinite_values_are_counted_and_change_nothing(bad, address, n):
    a = VmcAdapter()
    for i in range(n):
        values = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 40.0][:n]
        values[i] = bad
        assert a.handle(osc(address, "Head tracker", *values), 0.0) is None
    assert a.camera is None and a.trackers == {} and a.head_source == "none"
    counts(a, datagrams=n, nonfinite=n)


def test_a_named_head_tracker_moves_the_head_other_trackers_are_only_kept():
    a = VmcAdapter()
    turn = unity_quat((0, 1, 0), 30)
    a.handle(bundle(osc("/VMC/Ext/Tra/Pos", "LHR-FOOT", 0.1, 0.05, 0.0, *unity_quat((1, 0, 0), 90)),
                    osc("/VMC/Ext/Tra/Pos", "HeadTracker", 0.0, 1.6, 0.1, *turn)), 0.0)
    f = a.handle(jaw(0.5), 0.1)
    assert a.head_source == "tracker" and set(a.trackers) == {"LHR-FOOT", "HeadTracker"}
    np.testing.assert_allclose(f.head_rotation, (turn[0], -turn[1], -turn[2], turn[3]), atol=1e-6)
    assert f.head_translation is None  # a room position, not a head offset
    kind, pos, _ = a.trackers["HeadTracker"]
    assert kind == "tracker"
    np.testing.assert_allclose(pos, (0.0, 1.6, 0.1), atol=1e-6)
    counts(a, datagrams=2, frames=1)


def test_an_hmd_is_a_head_tracker_and_the_head_bone_wins_once_it_comes():
    a = VmcAdapter()
    hmd = unity_quat((1, 0, 0), 20)
    bone = unity_quat((0, 0, 1), 10)
    a.handle(osc("/VMC/Ext/Hmd/Pos", "HMD-1", 0.0, 1.7, 0.0, *hmd), 0.0)
    np.testing.assert_allclose(a.handle(jaw(0.1), 0.1).head_rotation, (hmd[0], -hmd[1], -hmd[2], hmd[3]), atol=1e-6)
    a.handle(osc("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.1, 0.0, *bone), 0.2)
    a.handle(osc("/VMC/Ext/Hmd/Pos", "HMD-1", 0.0, 1.7, 0.0, *hmd), 0.3)  # no longer moves the head
    f = a.handle(jaw(0.2), 0.4)
    assert a.head_source == "bone"
    np.testing.assert_allclose(f.head_rotation, (bone[0], -bone[1], -bone[2], bone[3]), atol=1e-6)
    counts(a, datagrams=5, frames=2)


def test_tracker_serials_are_bounded():
    a = VmcAdapter()
    for i in range(MAX_TRACKERS + 10):
        a.handle(osc("/VMC/Ext/Tra/Pos", f"LHR-{i}", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), 0.0)
    a.handle(osc("/VMC/Ext/Tra/Pos", "LHR-0", 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), 0.0)  # known: updated
    assert len(a.trackers) == MAX_TRACKERS
    np.testing.assert_allclose(a.trackers["LHR-0"][1], (-1.0, 0.0, 0.0))
    counts(a, datagrams=MAX_TRACKERS + 11, unknown_address=10)


SEED = 6


def _mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    how = rng.randrange(4)
    if how == 0:
        for _ in range(rng.randint(1, 6)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
    elif how == 1:
        del b[rng.randrange(len(b)):]
    elif how == 2:  # a float argument set to something odd
        i = len(b) - 4 * rng.randint(1, 8)
        b[i:i + 4] = struct.pack(">f", rng.choice([math.nan, math.inf, -math.inf, 3e38, 0.0]))
    else:
        i = rng.randrange(len(b))
        b[i:i] = rng.randbytes(rng.randint(1, 16))
    return bytes(b)


def test_fuzzed_new_addresses_never_raise_and_valid_frames_still_come():
    """20,000 mutated Cam / Tra / Hmd / Head datagrams; every one is counted once as a datagram, none raises,
    and a clean blend frame and head bone afterwards decode exactly."""
    rng = random.Random(SEED)
    q = unity_quat((0, 1, 0), 25)
    pool = [osc("/VMC/Ext/Cam", "Camera", 0.5, 1.4, 2.0, *q, 35.0),
            osc("/VMC/Ext/Tra/Pos", "HeadTracker", 0.0, 1.6, 0.1, *q),
            osc("/VMC/Ext/Hmd/Pos", "HMD", 0.0, 1.7, 0.0, *q),
            bundle(osc("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.1, 0.0, *q), osc("/VMC/Ext/Blend/Val", "JawOpen", 0.3),
                   osc("/VMC/Ext/Blend/Apply"))]
    a = VmcAdapter()
    n = 20_000
    for i in range(n):
        a.handle(_mutate(rng, rng.choice(pool)), i * 1e-3)
    assert a.counters["datagrams"] == n and a.counters["internal_error"] == 0
    assert len(a.trackers) <= MAX_TRACKERS
    a.handle(osc("/VMC/Ext/Blend/Apply"), 30.0)  # flush whatever a damaged datagram left pending
    a.handle(osc("/VMC/Ext/Bone/Pos", "Head", 0.0, 0.1, 0.0, *q), 30.5)
    f = a.handle(jaw(0.625), 31.0)
    assert f.weights[JAW] == pytest.approx(0.625)
    np.testing.assert_allclose(f.head_rotation, (q[0], -q[1], -q[2], q[3]), atol=1e-6)


def test_over_udp_a_head_tracker_camera_and_blend_values_through_the_process_receiver(udp_sender):
    """End to end over 127.0.0.1: the child-process receiver decodes a VSeeFace-like sender that names a
    head tracker and a camera but sends no bones; the frame has the tracker's head and the blend values."""
    from facepuppet.runtime.inputs.udp_process import UdpProcessSource

    from helpers.udp_helpers import poll_frame

    turn = unity_quat((0, 1, 0), 30)
    with UdpProcessSource(VmcAdapter(), port=0) as source:
        udp_sender.sendto(bundle(osc("/VMC/Ext/Cam", "Camera", 0.0, 1.4, 2.0, 0.0, 1.0, 0.0, 0.0, 30.0),
                                 osc("/VMC/Ext/Tra/Pos", "head", 0.0, 1.6, 0.0, *turn),
                                 osc("/VMC/Ext/Blend/Val", "JawOpen", 0.375), osc("/VMC/Ext/Blend/Apply")),
                          source.address)
        frame = poll_frame(source)
        counters = source.counters
    assert frame.weights[JAW] == pytest.approx(0.375)
    np.testing.assert_allclose(frame.head_rotation, (turn[0], -turn[1], -turn[2], turn[3]), atol=1e-6)
    assert counters["malformed"] == counters["unknown_address"] == counters["internal_error"] == 0
