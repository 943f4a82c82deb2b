"""Finding the next whole record of a session file after a damaged one, in time linear in the file's size.

A record (:mod:`~facepuppet.runtime.recording.session`) is ``u32 length | u32 crc32(payload) | u8 kind |
payload``; past a damaged record, reading resumes at the first later offset where a whole record verifies:
a known kind, a length within the file and at most :data:`MAX_PAYLOAD`, and the CRC. Checked one offset at a
time from scratch, each offset costs the length it claims, so a forged stretch whose every fourth byte
claims 64 KiB (``02 00 01 00`` repeated) took 12 s for 1 MiB and 54 s for 3 MiB: length times offsets.

Here no candidate costs more than a constant. CRC-32 is affine over GF(2), so the CRC of any stretch comes
from two prefix CRCs, as zlib's ``crc32_combine`` joins two::

    crc32(d[s:e]) = P(e) ^ T^(e-s)(P(s)),    P(i) = crc32(d[b:i]) for any base b <= s,

where ``T^n(v)`` multiplies ``v`` by x^(8n) modulo the CRC polynomial (bit-reflected, as zlib keeps it).
:class:`Prefixes` answers ``P(i)`` from checkpoints every :data:`CHECKPOINT` bytes, computed once, forward,
and shared by every resync of one read, plus at most CHECKPOINT bytes more; ``T^n`` is three
multiplications by tabled powers x^(8·d·256^k) (:func:`shift`). Offsets are scanned a window at a time
(NumPy), windows doubling from the damage, so at most about twice the bytes skipped are scanned.

Symbols: ``s``/``e`` payload start / end offsets, ``L = e - s`` the claimed length, ``P`` a prefix CRC.
"""

from __future__ import annotations

import array
import functools
import struct
import zlib
from collections.abc import Collection

import numpy as np

MAX_PAYLOAD = (1 << 24) - 1  # 16 MiB: the writer refuses more; far beyond any record a run writes
CHECKPOINT = 256  # bytes between the prefix CRCs kept (each lookup CRCs at most this many more)
DIRECT = 2 * CHECKPOINT  # a payload this short is CRC'd directly: cheaper than two lookups
NEAR = 32  # offsets right after a damaged record checked one by one (a record often follows at once)
FIRST_WINDOW = 256  # offsets scanned in the first window after them (then doubling)
MAX_WINDOW = 1 << 20  # offsets scanned at once at most (bounds the scan's temporary arrays)

_HEAD = struct.Struct("<IIB")  # payload length, crc32 of payload, kind
_POLY = 0xEDB88320  # CRC-32's polynomial, bit-reflected
_ONE = 1 << 31  # the polynomial 1, bit-reflected


def _mulmod(a: int, b: int) -> int:
    """a(x)·b(x) mod the CRC polynomial, both bit-reflected (zlib's ``multmodp``)."""
    p, m = 0, _ONE
    while m:
        if a & m:
            p ^= b
        m >>= 1
        b = (b >> 1) ^ _POLY if b & 1 else b >> 1
    return p


def _mulmod_array(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`_mulmod` of uint32 arrays, element by element."""
    p = np.zeros_like(a)
    b = b.copy()
    poly = np.uint32(_POLY)
    for bit in range(31, -1, -1):
        p ^= np.where((a >> np.uint32(bit)) & np.uint32(1), b, np.uint32(0))
        b = (b >> np.uint32(1)) ^ ((b & np.uint32(1)) * poly)
    return p


@functools.cache
def _powers() -> np.ndarray:
    """x^(8·d·256^k) mod the polynomial for k = 0, 1, 2 and d = 0..255: uint32 array of shape (3, 256)."""
    table = np.zeros((3, 256), np.uint32)
    step = 1 << 23  # x^8, bit-reflected
    for k in range(3):
        value = _ONE
        for d in range(256):
            table[k, d] = value
            value = _mulmod(value, step)
        step = value  # x^(8·256^(k+1))
    return table


def shift(values: np.ndarray, n: np.ndarray) -> np.ndarray:
    """T^n(v): each uint32 ``values[i]`` times x^(8·n[i]) modulo the polynomial (``n`` < 2^24), as CRC-ing
    ``n[i]`` zero bytes from that register would, without reading them."""
    values = np.asarray(values, np.uint32)
    n = np.asarray(n, np.int64)
    powers = _powers()
    if len(values) <= 16:  # a few: plain integers are quicker than 32 NumPy passes
        out = np.empty(len(values), np.uint32)
        for i, (v, k) in enumerate(zip(values.tolist(), n.tolist())):
            x = _mulmod(_mulmod(int(powers[0, k & 255]), int(powers[1, (k >> 8) & 255])), int(powers[2, k >> 16]))
            out[i] = _mulmod(v, x)
        return out
    x = _mulmod_array(_mulmod_array(powers[0, n & 255], powers[1, (n >> 8) & 255]), powers[2, n >> 16])
    return _mulmod_array(values, x)


class Prefixes:
    """Prefix CRCs ``P(i) = crc32(data[base:i])`` of one file's bytes, from checkpoints kept every CHECKPOINT
    bytes from ``base``; the base moves forward when asked for a stretch beyond every checkpoint, so over a
    whole read each byte is checkpointed at most once.

    Attributes
    ----------
    crc_bytes : int, bytes CRC'd so far (checkpoints, lookups, direct checks): the work, for tests and
        benchmarks
    """

    def __init__(self, data: bytes) -> None:
        self.data = memoryview(data)
        self.base = 0
        self._checkpoints = array.array("I", [0])  # 4 bytes each: a long scan keeps len(data) / 64 bytes
        self.crc_bytes = 0

    def reach(self, start: int) -> None:
        """Make ``start`` answerable: keep the checkpoints when they began at or before it, else begin anew."""
        end = self.base + (len(self._checkpoints) - 1) * CHECKPOINT
        if start < self.base or start > end:
            self.base, self._checkpoints = start, array.array("I", [0])

    def at(self, positions: np.ndarray) -> np.ndarray:
        """P(i) for each of ``positions`` (int64, each ``base <= i <= len(data)``): uint32 array."""
        positions = np.asarray(positions, np.int64)
        if not len(positions):
            return np.zeros(0, np.uint32)
        self._extend(int(positions.max()))
        j = (positions - self.base) // CHECKPOINT
        starts = self.base + j * CHECKPOINT
        self.crc_bytes += int((positions - starts).sum())
        # builtins mapped over builtins: no Python frame per position
        tails = map(self.data.__getitem__, map(slice, starts.tolist(), positions.tolist()))
        return np.fromiter(map(zlib.crc32, tails, map(self._checkpoints.__getitem__, j.tolist())), np.uint32,
                           len(positions))

    def _extend(self, i: int) -> None:
        """Checkpoints up to the one at or before offset ``i``."""
        cps, data, base = self._checkpoints, self.data, self.base
        for k in range(len(cps) - 1, (i - base) // CHECKPOINT):
            cps.append(zlib.crc32(data[base + k * CHECKPOINT:base + (k + 1) * CHECKPOINT], cps[k]))
            self.crc_bytes += CHECKPOINT

    def direct(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """crc32(data[s:e]) computed outright for each pair of ``starts``, ``ends``: uint32 array."""
        self.crc_bytes += int((ends - starts).sum())
        stretches = map(self.data.__getitem__, map(slice, starts.tolist(), ends.tolist()))
        return np.fromiter(map(zlib.crc32, stretches), np.uint32, len(starts))


def _candidates(data: bytes, start: int, stop: int, kinds: np.ndarray) -> tuple[np.ndarray, ...]:
    """(offsets, lengths, crcs) of the record heads at ``start <= at < stop`` whose kind is in ``kinds`` and whose
    length is 1..MAX_PAYLOAD and fits in the file: int64, int64, uint32 arrays in offset order."""
    end = len(data)
    head = np.frombuffer(data, np.uint8, count=stop - start + _HEAD.size - 1, offset=start).astype(np.uint32)
    n = stop - start
    length = head[0:n] | head[1:n + 1] << 8 | head[2:n + 2] << 16 | head[3:n + 3] << 24
    crc = head[4:n + 4] | head[5:n + 5] << 8 | head[6:n + 6] << 16 | head[7:n + 7] << 24
    at = np.arange(start, stop, dtype=np.int64)
    # no record is empty (each payload starts with its tag or JSON), and eight zero bytes and a kind byte,
    # common in OSC's zero padding, would otherwise verify as an empty record (crc32(b"") == 0)
    ok = np.isin(head[8:n + 8], kinds) & (length >= 1) & (length <= MAX_PAYLOAD)
    ok &= length.astype(np.int64) <= end - at - _HEAD.size
    return at[ok], length[ok].astype(np.int64), crc[ok]


def next_record(data: bytes, offset: int, kinds: Collection[int], prefixes: Prefixes) -> int | None:
    """Offset of the first record at or after ``offset`` whose kind is in ``kinds`` and whose length and CRC
    check; None when there is none. ``prefixes`` is the read's :class:`Prefixes` of ``data``."""
    last = len(data) - _HEAD.size + 1  # the last offset where a record head fits, plus one
    prefixes.reach(offset)
    start = min(offset + NEAR, last)
    for at in range(offset, start):
        kind = data[at + 8]
        length, crc, _ = _HEAD.unpack_from(data, at)
        if kind in kinds and 1 <= length <= min(MAX_PAYLOAD, len(data) - at - _HEAD.size) and _crc_of(
                prefixes, at + _HEAD.size, length) == crc:
            return at
    width, kind_codes = FIRST_WINDOW, np.fromiter(kinds, np.uint32)
    while start < last:
        stop = min(start + width, last)
        found = _first_verified(data, *_candidates(data, start, stop, kind_codes), prefixes)
        if found is not None:
            return found
        start, width = stop, min(width * 2, MAX_WINDOW)
    return None


def _crc_of(prefixes: Prefixes, s: int, length: int) -> int:
    """crc32 of the ``length`` bytes from ``s``, directly or from the prefix CRCs (as :func:`_first_verified`)."""
    if length <= DIRECT:
        prefixes.crc_bytes += length
        return zlib.crc32(prefixes.data[s:s + length])
    p_s, p_e = prefixes.at(np.array([s, s + length])).tolist()
    return p_e ^ int(shift(np.array([p_s]), np.array([length]))[0])


def _first_verified(data: bytes, at: np.ndarray, length: np.ndarray, crc: np.ndarray,
                    prefixes: Prefixes) -> int | None:
    """The first of the candidate offsets ``at`` whose payload's CRC is ``crc`` (None: none)."""
    if not len(at):
        return None
    s = at + _HEAD.size
    e = s + length
    short = length <= DIRECT
    verified = np.zeros(len(at), bool)
    near = np.flatnonzero(short)
    if len(near):
        verified[near] = prefixes.direct(s[near], e[near]) == crc[near]
    far = np.flatnonzero(~short)
    if len(far):
        p_s, p_e = prefixes.at(s[far]), prefixes.at(e[far])
        verified[far] = (p_e ^ shift(p_s, length[far])) == crc[far]
    hits = np.flatnonzero(verified)
    return int(at[hits[0]]) if len(hits) else None
