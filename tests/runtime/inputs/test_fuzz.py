"""Fuzz: >= 100,000 random and mutated datagrams against the input adapters and a live UdpSource.

Per input kind, N_DIRECT datagrams go straight to ``handle()`` and N_LIVE go
over loopback UDP to a running :class:`UdpSource`; afterwards valid datagrams
must still give frames with the right values, and nothing may have escaped
(``internal_error`` stays 0 in the adapters and the receive thread). The OSC
decoder is also checked against python-osc on the mutated corpus. Seeded, so a
failure reproduces.
"""

from __future__ import annotations

import logging
import math
import random
import socket
import struct
import time

import numpy as np
import pytest
from pythonosc.osc_packet import OscPacket

from facepuppet.runtime.inputs.kinds import INPUT_KINDS, make_adapter
from facepuppet.runtime.inputs.livelinkface import encode_llf_packet
from facepuppet.runtime.inputs.osc import UNSUPPORTED, decode
from facepuppet.runtime.inputs.udp import UdpSource
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal

from helpers.openseeface_sender import osf_record
from helpers.osc_helpers import bundle, msg
from helpers.phone_senders import ARKIT_52, ifm_frame, vts_frame

SEED = 3
N_DIRECT = 16_000  # per kind: 80,000 in all
N_LIVE = 4_000     # per kind over loopback: 20,000 in all
DEADLINE_S = 5.0
JAW = ARKIT_NAMES.index("jawOpen")
TAGS = "ifsbdhTFNrmtcSI[]x\x00"


MARKER_NAMES = tuple(f"m{i}" for i in range(8))
MARKERS = np.arange(24, dtype="<f4").reshape(8, 3)


def valid(kind: str, jaw: float) -> list[bytes]:
    """Datagrams of ``kind`` that end in a frame with jawOpen = jaw (markers: MARKERS)."""
    if kind == "vmc":
        return [msg("/VMC/Ext/Blend/Apply").dgram,  # flushes whatever a damaged datagram left pending
                bundle(msg("/VMC/Ext/Blend/Val", "JawOpen", jaw), msg("/VMC/Ext/Blend/Apply"))]
    if kind == "facecap":
        return [bundle(msg("/W", 24, jaw), msg("/HT", 0.0, 0.0, 1.0))]
    if kind == "faceosc":
        return [bundle(msg("/found", 1), msg("/raw", *([jaw] * 132)))]
    if kind == "markers":
        return [bundle(msg("/facepuppet/markers/layout", 1, *MARKER_NAMES),
                       msg("/facepuppet/markers/frame", 1, 5, (1.0, "d"), ((MARKERS * jaw).tobytes(), "b")))]
    if kind == "openseeface":
        return [osf_record(features={"mouth_open": jaw})]
    if kind == "ifacialmocap":
        return [ifm_frame({"jawOpen": jaw * 100})]
    if kind == "vtubestudio":
        return [vts_frame({"jawOpen": jaw})]
    weights = [0.0] * 52
    weights[JAW] = jaw
    return [encode_llf_packet(weights, head=(0.1, 0.0, 0.0), number=9)]


def drives(kind: str, frame, jaw: float) -> bool:
    if frame is None:
        return False
    if kind == "markers":
        return np.array_equal(frame.markers, MARKERS * np.float32(jaw))
    if kind == "faceosc":
        return frame.markers is not None and bool(np.all(frame.markers[:, :2] == np.float32(jaw)))
    return abs(float(frame.weights[JAW]) - jaw) < 1e-6


def seeds(kind: str) -> list[bytes]:
    """Valid datagrams to mutate, a few per kind and address."""
    names = [pascal(n) for n in ARKIT_NAMES[::9]]
    out = {
        "vmc": [bundle(*(msg("/VMC/Ext/Blend/Val", n, 0.5) for n in names + ["Joy", "A"]),
                       msg("/VMC/Ext/Blend/Apply")),
                bundle(msg("/VMC/Ext/Bone/Pos", "Head", 0.0, 1.5, 0.0, 0.0, 0.0, 0.0, 1.0),
                       msg("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)),
                msg("/VMC/Ext/OK", 1, 3, 0, 1).dgram, msg("/VMC/Ext/T", 1.5).dgram],
        "facecap": [bundle(*(msg("/W", i, 0.5) for i in range(0, 52, 7)), msg("/HR", 1.0, 2.0, 3.0),
                           msg("/HRQ", 0.0, 0.0, 0.0, 1.0), msg("/HT", 0.0, 0.0, 1.0),
                           msg("/ELR", 1.0, 2.0), msg("/ERR", 1.0, 2.0)),
                    msg("/W", 24, 0.5).dgram],
        "faceosc": [bundle(msg("/found", 1), msg("/pose/position", 320.0, 240.0), msg("/pose/scale", 4.0),
                           msg("/pose/orientation", 0.1, 0.2, 0.3), msg("/gesture/mouth/width", 14.0),
                           msg("/gesture/mouth/height", 2.0), msg("/gesture/eyebrow/left", 7.0),
                           msg("/gesture/eye/right", 2.8), msg("/gesture/jaw", 21.0)),
                    msg("/raw", *([1.0] * 132)).dgram],
        "markers": [msg("/facepuppet/markers/layout", 1, *MARKER_NAMES).dgram,
                    msg("/facepuppet/markers/frame", 1, 5, (1.0, "d"), (MARKERS.tobytes(), "b")).dgram,
                    valid("markers", 0.5)[0]],
        "livelinkface": [encode_llf_packet([0.5] * 52, head=(0.1, 0.2, 0.3), name="Phone")],
        "openseeface": [osf_record(features={"mouth_open": 0.5}),
                        osf_record(face_id=1, fit=0) + osf_record(face_id=2, right_open=0.1)],
        "ifacialmocap": [ifm_frame({n: 50 for n in ARKIT_52}, head=(1, 2, 3, 0.1, 0.2, 0.3), version=1),
                         ifm_frame({n: -5 for n in ARKIT_52[::5]})],
        "vtubestudio": [vts_frame({n: 0.5 for n in ARKIT_52}, rotation=(1.0, 2.0, 3.0)),
                        vts_frame({}, found=False)],
    }
    return out[kind]


def mutate(rng: random.Random, pool: list[bytes]) -> bytes:
    data = bytearray(rng.choice(pool))
    how = rng.randrange(8)
    if how == 0:  # bit flips
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
    elif how == 1:  # truncation
        del data[rng.randrange(len(data)):]
    elif how == 2:  # random bytes behind a plausible start
        prefix = rng.choice([b"", b"/", b"#bundle\x00", bytes(data[:rng.randrange(1, 64)])])
        data = bytearray(prefix + rng.randbytes(rng.randrange(0, 300)))
    elif how == 3:  # random type tags
        comma = data.find(b",")
        if comma >= 0:
            for i in range(comma + 1, min(len(data), comma + 1 + rng.randint(1, 12))):
                data[i] = ord(rng.choice(TAGS))
    elif how == 4:  # splice two datagrams
        other = rng.choice(pool)
        data = data[:rng.randrange(len(data) + 1)] + other[rng.randrange(len(other) + 1):]
    elif how == 5:  # an int32 field (size, count, index) set to an odd value
        if len(data) >= 4:
            i = rng.randrange(0, len(data) - 3) & ~3
            value = rng.choice([-4, -1, 0, 1, 3, 0x7FFFFFFF, -0x80000000, len(data), rng.getrandbits(31)])
            data[i:i + 4] = struct.pack(">i", value)
    elif how == 6:  # random length of random bytes
        data = bytearray(rng.randbytes(rng.randrange(0, 2000)))
    else:  # float fields set to non-finite or huge values
        for _ in range(rng.randint(1, 4)):
            if len(data) >= 4:
                i = rng.randrange(0, len(data) - 3) & ~3
                data[i:i + 4] = struct.pack(">f", rng.choice([math.nan, math.inf, -math.inf, 3e38, -1e-40]))
    return bytes(data)


@pytest.mark.parametrize("kind", list(INPUT_KINDS))
def test_fuzz_direct_then_live(kind):
    rng = random.Random(f"{SEED}-{kind}")
    pool = seeds(kind)
    adapter = make_adapter(kind)
    for i in range(N_DIRECT):
        adapter.handle(mutate(rng, pool), i * 0.001)
    assert adapter.counters["datagrams"] == N_DIRECT and adapter.counters["internal_error"] == 0
    t = N_DIRECT * 0.001
    frame = None
    for data in valid(kind, 0.375):
        t += 1.0
        frame = adapter.handle(data, t)
    assert drives(kind, frame, 0.375), (kind, frame)

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        with UdpSource(make_adapter(kind), port=0) as source:
            for i in range(N_LIVE):
                data = mutate(rng, pool)
                if data:  # an empty datagram is legal UDP, but keep the count of real ones simple
                    sock.sendto(data, source.address)
                if i % 256 == 0:
                    time.sleep(0.001)  # let the receiver keep up a little; drops are fine
            end = time.monotonic() + DEADLINE_S
            ok = False
            while time.monotonic() < end and not ok:
                for data in valid(kind, 0.625):
                    sock.sendto(data, source.address)
                time.sleep(0.01)
                ok = drives(kind, source.latest()[0], 0.625)
            counters = source.counters
    finally:
        sock.close()
    assert ok, f"{kind}: no valid frame within {DEADLINE_S} s after the fuzz; counters {counters}"
    assert counters["internal_error"] == 0, source.last_error
    assert counters["packets"] > N_LIVE // 2  # most of the flood really reached the live server


def test_decoder_agrees_with_python_osc():
    """Wherever decode() accepts a mutated datagram, python-osc reads the same messages."""
    rng = random.Random(f"{SEED}-reference")
    pool = [d for kind in ("vmc", "facecap", "faceosc", "markers") for d in seeds(kind)]
    compared = 0
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)  # python-osc warns through the root logger
    try:
        for _ in range(8000):
            data = mutate(rng, pool)
            ours = decode(data)
            if ours is None or any(p is UNSUPPORTED for _, params in ours for p in params):
                continue
            reference = [(m.message.address, m.message.params) for m in OscPacket(data).messages]
            assert repr(ours) == repr(reference), data
            compared += 1
    finally:
        logging.disable(previous)
    assert compared > 1000
