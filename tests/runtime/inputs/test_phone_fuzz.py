"""Fuzz with exact counters: ifacialmocap and vtubestudio, >= 20,000 generated datagrams per kind.

Each datagram is built by a seeded generator that knows, from the published
facts and the documented drop rules, what it must give: a frame (and how many
unknown names it carries), tracking lost, or one drop counter. The counters
after the run must equal the generator's tally exactly, first straight into
``handle()`` (N_DIRECT), then over loopback UDP into both receivers
(N_LIVE each, sent in batches, each batch waited for, so nothing is lost and
the count is exact). Then randomly damaged datagrams (truncation, bit flips,
splices) whose outcome nobody knows in advance: every one must land in
exactly one counter and nothing may escape (``internal_error`` 0).
"""

from __future__ import annotations

import json
import random
import socket
from collections import Counter

import pytest

from facepuppet.runtime.inputs.ifacialmocap import MAX_PACKET
from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.inputs.udp import UdpSource
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vtubestudio import MAX_MESSAGE

from helpers.phone_senders import ARKIT_52, ifm_name, vts_frame
from helpers.udp_helpers import wait_for

SEED = 16
N_DIRECT = 20_000
N_LIVE = 1_500
N_DAMAGED = 5_000
BATCH = 50
OUTCOMES = {"ifacialmocap": ("frames", "malformed", "oversized", "nonfinite", "internal_error"),
            "vtubestudio": ("frames", "face_lost", "malformed", "oversized", "nonfinite", "internal_error")}
JUNK = ["abc", "1x", "1.2.3", "", "0x1g", "one"]
NONFINITE = ["nan", "inf", "-inf", "NaN", "Infinity", "1e39", "-4e38"]


def _ifm_case(rng: random.Random) -> tuple[bytes, str, int]:
    """(datagram, expected outcome, unknown names it carries when it gives a frame)."""
    version = rng.choice((1, 2))
    names = rng.sample(ARKIT_52, rng.randint(1, 52))
    low = 0 if version == 1 else -100
    values = {n: rng.randint(low, 100) for n in names}
    head = tuple(round(rng.uniform(-90, 90), 3) for _ in range(6)) if rng.random() < 0.8 else None
    eyes = [tuple(round(rng.uniform(-30, 30), 2) for _ in range(3)) if rng.random() < 0.7 else None
            for _ in range(2)]
    sep = "&" if version == 2 else "-"
    unknown = rng.randint(0, 3)
    extra = "".join(f"stray{i}{rng.randint(0, 9)}{sep}{rng.randint(0, 100)}|" for i in range(unknown))
    fault = rng.choices(("none", "junk", "nonfinite", "head_len", "eye_len", "dup", "utf8", "oversized"),
                        weights=(10, 2, 2, 1, 1, 1, 1, 1))[0]
    if fault == "junk":
        values[rng.choice(names)] = rng.choice(JUNK)
    elif fault == "nonfinite":
        values[rng.choice(names)] = rng.choice(NONFINITE)
    elif fault == "head_len":
        head = tuple(range(rng.choice((0, 1, 5, 7, 9))))
    elif fault == "eye_len":
        eyes[0] = tuple(range(rng.choice((1, 2, 4))))
    elif fault == "dup":
        dup = rng.choice(names)
        extra += f"{ifm_name(dup)}{sep}{rng.randint(0, 100)}|"
    elif fault == "oversized":
        extra += "pad" + "x" * (MAX_PACKET + 1) + f"{sep}1|"
    data = _ifm_text(values, head, eyes, sep, extra)
    if fault == "utf8":
        cut = rng.randrange(len(data))
        data = data[:cut] + b"\xff" + data[cut:]
    expected = {"none": "frames", "junk": "malformed", "nonfinite": "nonfinite", "head_len": "malformed",
                "eye_len": "malformed", "dup": "malformed", "utf8": "malformed", "oversized": "oversized"}[fault]
    return data, expected, unknown if expected == "frames" else 0


def _ifm_text(values: dict, head, eyes, sep: str, extra: str) -> bytes:
    """Like ifm_frame, but values may be any text (the faults)."""
    items = "".join(f"{ifm_name(k)}{sep}{v}|" for k, v in values.items())
    text = items + extra
    if head is not None:
        text += "=head#" + ",".join(str(x) for x in head) + "|"
    for label, eye in zip(("rightEye", "leftEye"), eyes):
        if eye is not None:
            text += f"{label}#" + ",".join(str(x) for x in eye) + "|"
    return text.encode("utf-8")


def _vts_case(rng: random.Random) -> tuple[bytes, str, int]:
    names = rng.sample(ARKIT_52, rng.randint(1, 52))
    values = {n: round(rng.random(), 6) for n in names}

    def vec(p=0.8):
        return tuple(round(rng.uniform(-60, 60), 4) for _ in range(3)) if rng.random() < p else None

    found = rng.random() < 0.85
    obj = json.loads(vts_frame(values, found=found, rotation=vec(0.9), position=vec(), eye_left=vec(),
                               eye_right=vec(), timestamp=rng.randrange(1 << 41), hotkey=rng.randint(-1, 8)))
    unknown = rng.randint(0, 3)
    obj["BlendShapes"] += [{"k": f"Stray{i}", "v": 0.5} for i in range(unknown)]
    rng.shuffle(obj["BlendShapes"])
    fault = rng.choices(("none", "type", "nonfinite", "truncated", "oversized"), weights=(10, 3, 2, 2, 1))[0]
    raw = None
    if fault == "type":
        key = rng.choice(("FaceFound", "BlendShapes", "entry_k", "entry_v", "Rotation", "Hotkey", "Timestamp"))
        if key == "entry_k":
            obj["BlendShapes"][0]["k"] = rng.choice((5, None, ["JawOpen"]))
        elif key == "entry_v":
            obj["BlendShapes"][0]["v"] = rng.choice(("0.5", None, True, [0.5]))
        elif key == "Rotation":
            obj["Rotation"] = rng.choice(([1, 2, 3], "r", 5, {"x": 1, "y": 2}, {"x": "1", "y": 2, "z": 3}))
        elif key == "FaceFound":
            obj["FaceFound"] = rng.choice((1, 0, "true", None, [True]))
        elif key == "BlendShapes":
            obj["BlendShapes"] = rng.choice(("x", 5, {"k": "JawOpen", "v": 1}))
        elif key == "Hotkey":
            obj["Hotkey"] = rng.choice((1.5, "3", True, [1]))
        else:
            obj["Timestamp"] = rng.choice(("now", True, [1], {"ms": 1}))
    elif fault == "nonfinite":
        literal = rng.choice(("NaN", "Infinity", "-Infinity", "1e400", "1e39"))
        slot = rng.choice(("v", "x"))
        if slot == "v" or "Rotation" not in obj:
            obj["BlendShapes"][0]["v"] = "@@"
        else:
            obj["Rotation"]["x"] = "@@"
        raw = json.dumps(obj).replace('"@@"', literal).encode()
    elif fault == "truncated":
        full = json.dumps(obj).encode()
        raw = full[:rng.randrange(len(full))]
    elif fault == "oversized":
        obj["Pad"] = "x" * (MAX_MESSAGE + 1)
    data = raw if raw is not None else json.dumps(obj).encode()
    if fault == "none":
        expected = "frames" if found else "face_lost"
    else:
        expected = {"type": "malformed", "nonfinite": "nonfinite", "truncated": "malformed",
                    "oversized": "oversized"}[fault]
    return data, expected, unknown if expected == "frames" else 0


CASES = {"ifacialmocap": _ifm_case, "vtubestudio": _vts_case}


def corpus(kind: str, n: int, tag: str) -> tuple[list[bytes], Counter]:
    """n generated datagrams and the exact counters they must give."""
    rng = random.Random(f"{SEED}-{kind}-{tag}")
    data, tally = [], Counter()
    for _ in range(n):
        d, outcome, unknown = CASES[kind](rng)
        data.append(d)
        tally[outcome] += 1
        tally["unknown_key"] += unknown
    tally["datagrams"] = n
    return data, tally


def exact(counters: dict, kind: str) -> dict:
    return {k: counters[k] for k in ("datagrams", "unknown_key", *OUTCOMES[kind])}


def expected(tally: Counter, kind: str) -> dict:
    return {k: tally.get(k, 0) for k in ("datagrams", "unknown_key", *OUTCOMES[kind])}


@pytest.mark.parametrize("kind", list(CASES))
def test_generated_datagrams_give_exact_counters(kind):
    data, tally = corpus(kind, N_DIRECT, "direct")
    # every fault class really occurs, in numbers
    assert all(tally.get(k, 0) > 200 for k in OUTCOMES[kind] if k != "internal_error"), tally
    adapter = make_adapter(kind)
    for i, d in enumerate(data):
        adapter.handle(d, i * 0.001)
    assert exact(adapter.counters, kind) == expected(tally, kind)


def _flood(source, data: list[bytes]) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for start in range(0, len(data), BATCH):
            for d in data[start:start + BATCH]:
                sock.sendto(d, source.address)
            done = start + len(data[start:start + BATCH])
            wait_for(lambda done=done: source.counters.get("packets", 0) >= done and
                     source.counters.get("datagrams", 0) >= done, f"{done} datagrams decoded")
    finally:
        sock.close()


@pytest.mark.parametrize("receiver", [UdpSource, UdpProcessSource], ids=["thread", "process"])
@pytest.mark.parametrize("kind", list(CASES))
def test_both_receivers_decode_with_exact_counters(kind, receiver):
    data, tally = corpus(kind, N_LIVE, f"live-{receiver.__name__}")
    data = [d for d in data if len(d) <= 65507]  # all of them: the largest is MAX + a little
    assert len(data) == N_LIVE
    with receiver(make_adapter(kind), port=0) as source:
        _flood(source, data)
        counters = source.counters
    assert exact(counters, kind) == expected(tally, kind)
    assert counters["packets"] == N_LIVE and counters["internal_error"] == 0


def _damage(rng: random.Random, pool: list[bytes]) -> bytes:
    d = bytearray(rng.choice(pool))
    how = rng.randrange(4)
    if how == 0:
        del d[rng.randrange(len(d) + 1):]
    elif how == 1:
        for _ in range(rng.randint(1, 6)):
            i = rng.randrange(len(d))
            d[i] ^= 1 << rng.randrange(8)
    elif how == 2:
        other = rng.choice(pool)
        d = d[:rng.randrange(len(d) + 1)] + other[rng.randrange(len(other) + 1):]
    else:
        i = rng.randrange(len(d) + 1)
        d[i:i] = rng.randbytes(rng.randrange(1, 40))
    return bytes(d)


@pytest.mark.parametrize("kind", list(CASES))
def test_damaged_datagrams_each_land_in_one_counter(kind):
    pool, _ = corpus(kind, 200, "pool")
    pool = [d for d in pool if len(d) < 4000]
    rng = random.Random(f"{SEED}-{kind}-damage")
    adapter = make_adapter(kind)
    for i in range(N_DAMAGED):
        adapter.handle(_damage(rng, pool), i * 0.001)
    c = adapter.counters
    assert c["internal_error"] == 0
    assert c["datagrams"] == N_DAMAGED == sum(c[k] for k in OUTCOMES[kind])
