"""Resynchronising after a damaged record: the same offsets as a plain scan, in work linear in the file's size."""

from __future__ import annotations

import random
import struct
import time
import warnings
import zlib

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording import resync, session
from facepuppet.runtime.recording.records import RecordKind, encode_audio
from facepuppet.runtime.recording.resync import MAX_PAYLOAD, Prefixes, next_record, shift
from facepuppet.runtime.recording.session import SessionWriter, _record, read_session

KINDS = frozenset(int(k) for k in RecordKind if k != RecordKind.HEADER)


def plain_next_record(data: bytes, offset: int) -> int | None:
    """The reference: every offset in turn, its payload CRC'd from scratch."""
    for at in range(offset, len(data) - 9 + 1):
        length, crc, kind = struct.unpack_from("<IIB", data, at)
        if kind in KINDS and 1 <= length <= min(MAX_PAYLOAD, len(data) - at - 9) and \
                zlib.crc32(data[at + 9:at + 9 + length]) == crc:
            return at
    return None


def test_shift_is_crc32_over_zero_bytes():
    """T^n(v) multiplies by x^(8n): what CRC-ing n zero bytes from register v does (zlib's conventions)."""
    rng = random.Random(3)
    for count in (1, 5, 40):  # a few: plain integers; more: NumPy
        values = [rng.getrandbits(32) for _ in range(count)]
        lengths = [rng.choice([0, 1, 255, 256, 65535, 65536, 70001, MAX_PAYLOAD]) for _ in range(count)]
        expected = [zlib.crc32(bytes(n), v ^ 0xFFFFFFFF) ^ 0xFFFFFFFF for v, n in zip(values, lengths)]
        assert shift(np.array(values, np.uint32), np.array(lengths)).tolist() == expected


def test_the_crc_of_any_stretch_comes_from_two_prefixes():
    rng = np.random.default_rng(5)
    data = rng.integers(0, 256, 20_000, np.uint8).tobytes()
    prefixes = Prefixes(data)
    for base in (0, 700, 4_000):  # a later base begins the checkpoints anew
        prefixes.reach(base)
        s = np.sort(rng.integers(base, len(data), 500))
        e = np.minimum(s + rng.integers(0, 3000, 500), len(data))
        crc = prefixes.at(e) ^ shift(prefixes.at(s), e - s)
        assert crc.tolist() == [zlib.crc32(data[a:b]) for a, b in zip(s.tolist(), e.tolist())]


def _records(rng: random.Random, n: int) -> bytes:
    out = []
    for _ in range(n):
        size = rng.choice([1, 5, 14, 60, 300, 600, 2000])
        out.append(_record(RecordKind(rng.choice(sorted(KINDS))), rng.randbytes(size)))
    return b"".join(out)


def test_next_record_finds_what_the_plain_scan_finds_in_damaged_and_forged_bytes():
    rng = random.Random(11)
    for trial in range(60):
        data = bytearray(_records(rng, 30))
        for _ in range(rng.randint(1, 6)):  # flipped bits, zeroed stretches, forged heads claiming lengths
            at = rng.randrange(len(data) - 12)
            choice = rng.randrange(3)
            if choice == 0:
                data[at] ^= 1 << rng.randrange(8)
            elif choice == 1:
                data[at:at + rng.randint(1, 40)] = bytes(min(40, len(data) - at))[:len(data[at:at + 40])]
            else:
                data[at:at + 9] = struct.pack("<IIB", rng.choice([3, 513, 5000, 70000]), rng.getrandbits(32),
                                              rng.choice(sorted(KINDS)))
        data = bytes(data)
        prefixes = Prefixes(data)
        offset = 0
        while offset is not None and offset < len(data):
            found = next_record(data, offset, KINDS, prefixes)
            assert found == plain_next_record(data, offset), (trial, offset)
            offset = None if found is None else found + 1


def _forged(path, region: bytes) -> None:
    """A session file: three frames, the forged region, three more frames (what reading resumes at)."""
    frames = [Frame(t=i / 60, source="vmc", channels=("jawOpen",), weights=np.array([0.3], np.float32))
              for i in range(6)]
    with SessionWriter(path, overwrite=True) as w:
        for f in frames[:3]:
            w.write_frame(f)
    head = path.read_bytes()
    body = b"".join(_record(RecordKind.FRAME, session.encode_frame(f, 0)) for f in frames[3:])  # layout 0
    path.write_bytes(head + region + body)


class _Counted(Prefixes):
    """Prefixes that remember each instance, so a test reads the work a whole read_session did."""

    made: list = []

    def __init__(self, data):
        super().__init__(data)
        _Counted.made.append(self)


@pytest.mark.parametrize("pattern", ["02001000", "02000100", "0200"])
def test_resync_past_a_forged_region_is_linear_in_its_size(tmp_path, monkeypatch, pattern):
    """The issue's region of ``02 00 10 00`` repeated makes every fourth byte claim a 1 MiB record (1 MiB took
    43 s, 3 MiB over a minute); ``02 00 01 00`` claims 64 KiB, ``02 00`` every other byte 128 KiB. Each now
    completes and keeps all six frames, its CRC work at most 2 x CHECKPOINT bytes per byte skipped (a plain scan
    spent the claimed length on each); where the claims are short next to 1 MiB (the issue's claims fit in
    the 3 MiB region, hardly in the 1 MiB one), 3 MiB costs about three times the work of 1 MiB."""
    monkeypatch.setattr(session, "Prefixes", _Counted)
    work, seconds = {}, {}
    for mib in (1, 3):
        path = tmp_path / f"forged{mib}.fps"
        region = bytes.fromhex(pattern) * (mib * (1 << 20) // (len(pattern) // 2))
        _forged(path, region)
        _Counted.made.clear()
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = read_session(path)
        seconds[mib] = time.perf_counter() - start
        work[mib] = sum(p.crc_bytes for p in _Counted.made)
        assert len(s.frames) == 6 and s.skipped_bytes == len(region)
        assert work[mib] <= 2 * resync.CHECKPOINT * len(region)  # a plain scan: up to MAX_PAYLOAD per offset
    print(f"resync past {pattern}: CRC bytes {work}, seconds {seconds}")
    if pattern != "02001000":
        assert 2.0 <= work[3] / work[1] <= 4.5


def test_many_small_damaged_stretches_each_cost_a_constant(tmp_path, monkeypatch):
    """One bad byte before each of thousands of small records: each resync finds the record at once."""
    monkeypatch.setattr(session, "Prefixes", _Counted)
    unit = b"\xff" + _record(RecordKind.AUDIO, encode_audio(0.5, -20.0))
    work = {}
    for n in (2000, 6000):
        path = tmp_path / f"many{n}.fps"
        with SessionWriter(path, overwrite=True):
            pass
        path.write_bytes(path.read_bytes() + unit * n)
        _Counted.made.clear()
        with pytest.warns(UserWarning, match=f"{n} damaged stretches"):
            s = read_session(path)
        assert len(s.audio_levels) == n
        work[n] = sum(p.crc_bytes for p in _Counted.made)
    assert work[6000] <= 3.5 * work[2000]
