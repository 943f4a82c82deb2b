"""OpenSeeFace fuzz with exact counters: 24,000 datagrams straight to ``handle()``, 2,000 over loopback UDP.

Every datagram's outcome is predicted by an oracle written here with :mod:`struct` (whole number of
records? fit byte? every float finite?), independently of the decoder's NumPy reading, and the
adapter's counters must equal the oracle's tally exactly. Seeded, so a failure reproduces.
"""

from __future__ import annotations

import math
import random
import socket
import struct

import pytest

from facepuppet.runtime.inputs.openseeface import OpenSeeFaceAdapter
from facepuppet.runtime.inputs.udp import UdpSource

from helpers.openseeface_sender import FEATURE_ORDER, SIZE, float_offsets, osf_record
from helpers.udp_helpers import wait_for

SEED = 16
N_DIRECT = 24_000
N_LIVE = 2_000
BATCH = 50        # datagrams in flight at once over loopback (well inside the receive buffer)
MAX_BYTES = 36 * SIZE
OFFSETS = float_offsets()


def oracle(data: bytes, face_id: int | None) -> str:
    """The counter one datagram must raise besides ``datagrams``: frames / malformed / ..."""
    if len(data) > MAX_BYTES:
        return "oversized"
    n, rest = divmod(len(data), SIZE)
    if n == 0 or rest:
        return "malformed"
    ids = [struct.unpack_from("<i", data, k * SIZE + 8)[0] for k in range(n)]
    if face_id is None:
        k = 0
    elif face_id in ids:
        k = ids.index(face_id)
    else:
        return "other_face"
    base = k * SIZE
    fit = data[base + 28]
    if fit > 1:
        return "malformed"
    floats = [struct.unpack_from("<d", data, base)[0]] + [struct.unpack_from("<f", data, base + at)[0]
                                                          for at in OFFSETS]
    if not all(math.isfinite(v) for v in floats):
        return "nonfinite"
    if fit:
        q = [struct.unpack_from("<f", data, base + 33 + 4 * i)[0] for i in range(4)]
        if not 1e-6 < math.sqrt(sum(c * c for c in q)) < 1e30:
            return "malformed"
        return "frames"
    return "frames+no_fit"


def random_record(rng: random.Random, face_id: int) -> bytes:
    q = [rng.uniform(-1, 1) for _ in range(4)]
    return osf_record(time=rng.uniform(0, 2e9), face_id=face_id, right_open=rng.uniform(-0.2, 1.2),
                      left_open=rng.uniform(-0.2, 1.2), fit=rng.choice([0, 1, 1, 1]), quaternion=q,
                      features={n: rng.uniform(-1.5, 1.5) for n in FEATURE_ORDER})


def datagram(rng: random.Random) -> bytes:
    how = rng.randrange(9)
    records = [random_record(rng, rng.randrange(4)) for _ in range(rng.randint(1, 3))]
    data = bytearray(b"".join(records))
    if how == 0:  # truncated or extended: lengths around the record boundaries
        cut = rng.randrange(len(data) + 1) if rng.random() < 0.5 else len(data) + rng.randint(1, SIZE)
        data = (data + bytes(SIZE))[:cut]
    elif how == 1:  # a non-finite value at a random float or the time of a random record
        k = rng.randrange(len(records)) * SIZE
        at = rng.choice(OFFSETS + [0])
        if at == 0:
            struct.pack_into("<d", data, k, rng.choice([math.nan, math.inf, -math.inf]))
        else:
            struct.pack_into("<f", data, k + at, rng.choice([math.nan, math.inf, -math.inf]))
    elif how == 2:  # bit flips anywhere
        for _ in range(rng.randint(1, 16)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
    elif how == 3:  # random bytes, a whole number of records long
        data = bytearray(rng.randbytes(SIZE * rng.randint(1, 2)))
    elif how == 4:  # random bytes of a random length
        data = bytearray(rng.randbytes(rng.randrange(0, 4 * SIZE)))
    elif how == 5:  # a fit byte of another value
        data[rng.randrange(len(records)) * SIZE + 28] = rng.randrange(256)
    elif how == 6:  # oversized, or exactly the largest legal size
        data = bytearray(records[0] * rng.choice([36, 37, 40]))
    elif how == 7:  # a zero quaternion
        data[33:49] = bytes(16)
    return bytes(data)  # how == 8: valid as made


@pytest.mark.parametrize("face_id", [None, 2])
def test_direct_fuzz_counters_are_exact(face_id):
    rng = random.Random(f"{SEED}-direct-{face_id}")
    adapter = OpenSeeFaceAdapter(face_id=face_id)
    want = {k: 0 for k in adapter.counters}
    n = N_DIRECT // 2
    for i in range(n):
        data = datagram(rng)
        outcome = oracle(data, face_id)
        for key in outcome.split("+"):
            want[key] += 1
        frame = adapter.handle(data, i * 0.01)
        assert (frame is not None) == outcome.startswith("frames"), (i, outcome)
    want["datagrams"] = n
    assert adapter.counters == want
    assert want["frames"] > n // 10 and want["malformed"] > n // 10 and want["nonfinite"] > 200
    assert want["oversized"] > 100 and want["no_fit"] > 100 and (face_id is None or want["other_face"] > 100)


def test_live_fuzz_over_loopback_counts_every_datagram_exactly():
    rng = random.Random(f"{SEED}-live")
    want: dict[str, int] = {}
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = 0
    try:
        with UdpSource(OpenSeeFaceAdapter(), port=0) as source:
            while sent < N_LIVE:
                for _ in range(BATCH):
                    data = datagram(rng)
                    while not data or len(data) > 65507:  # not sendable as one IPv4 datagram: make another
                        data = datagram(rng)
                    for key in oracle(data, None).split("+"):
                        want[key] = want.get(key, 0) + 1
                    sock.sendto(data, source.address)
                    sent += 1
                # wait until the receiver has counted the batch before the next (no loss to account for)
                wait_for(lambda n=sent: source.counters["datagrams"] == n, f"{sent} datagrams counted")
            counters = source.counters
    finally:
        sock.close()
    assert counters["internal_error"] == 0 and counters["packets"] == N_LIVE
    for key in ("frames", "malformed", "nonfinite", "oversized", "no_fit", "other_face"):
        assert counters[key] == want.get(key, 0), (key, counters, want)
