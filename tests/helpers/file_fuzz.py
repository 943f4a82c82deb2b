"""Mutations of real files for the file-fuzz tests: truncations, bit flips and type swaps, seeded.

``mutants(data, seed, n)`` yields ``(label, bytes)``; the same seed gives the
same cases on every machine. ``check_reader`` runs a reader on each mutant
and returns what went wrong: a reader may succeed or refuse with the
project's own error (a FacepuppetError naming the file); anything else (a
traceback, a refusal without the path, a RuntimeWarning) is a finding.
"""

from __future__ import annotations

import re
import struct
import warnings
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.recording.session import MAGIC

TOKEN = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?|[A-Za-z_][A-Za-z_0-9]*")
SWAPS = (b"abc", b"1e300", b"-1", b"nan", b"", b"\xff\xfe", b"[]", b"null", b"0", b"99999999999999999999",
         b"\"x\"", b"{}", b"inf", b"-0.0e-400", b",", b"\t", b"\n")


def truncations(data: bytes, rng: np.random.Generator, n: int) -> Iterator[tuple[str, bytes]]:
    cuts = {0, 1, 30, len(data) - 1, len(data) // 2}
    cuts.update(int(c) for c in rng.integers(0, max(len(data), 1), n))
    for cut in sorted(c for c in cuts if 0 <= c < len(data))[:n + 5]:
        yield f"truncated to {cut} bytes", data[:cut]


def bit_flips(data: bytes, rng: np.random.Generator, n: int) -> Iterator[tuple[str, bytes]]:
    for _ in range(n):
        out = bytearray(data)
        at = int(rng.integers(0, len(data)))
        bit = int(rng.integers(0, 8))
        out[at] ^= 1 << bit
        yield f"bit {bit} of byte {at} flipped", bytes(out)


def type_swaps(data: bytes, rng: np.random.Generator, n: int) -> Iterator[tuple[str, bytes]]:
    tokens = [m.span() for m in TOKEN.finditer(data)]
    if not tokens:
        return
    for _ in range(n):
        start, end = tokens[int(rng.integers(0, len(tokens)))]
        swap = SWAPS[int(rng.integers(0, len(SWAPS)))]
        yield f"token {data[start:end][:20]!r} at byte {start} swapped for {swap!r}", data[:start] + swap + data[end:]


def mutants(data: bytes, seed: int, n: int = 12) -> Iterator[tuple[str, bytes]]:
    """Truncations, bit flips and type swaps of ``data``: about 3n cases, the same for the same seed."""
    rng = np.random.default_rng(seed)
    yield from truncations(data, rng, n)
    yield from bit_flips(data, rng, n)
    yield from type_swaps(data, rng, n)


def outcome(read: Callable[[Path], object], path: Path) -> str | None:
    """None when ``read(path)`` succeeds or refuses properly; else what went wrong, in one line."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            read(path)
        except FacepuppetError as exc:
            if str(path) not in str(exc):
                return f"{type(exc).__name__} without the path: {exc}"
        except Exception as exc:  # noqa: BLE001 - a finding, reported
            if isinstance(exc, ValueError) and str(path) in str(exc):
                return f"not our error type ({type(exc).__name__}, path named): {str(exc)[:200]}"
            return f"traceback {type(exc).__name__}: {str(exc)[:200]}"
    runtime = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    if runtime:
        return f"RuntimeWarning leaked: {runtime[0].message}"
    return None


def check_reader(read: Callable[[Path], object], real: bytes, where: Path, suffix: str, seed: int,
                 n: int = 12, extra: Iterator[tuple[str, bytes]] = ()) -> list[str]:
    """Run ``read`` on every mutant of ``real`` (written under ``where``); the findings, labelled."""
    findings = []
    for i, (label, data) in enumerate([*mutants(real, seed, n), *extra]):
        path = where / f"mutant{i}{suffix}"
        path.write_bytes(data)
        problem = outcome(read, path)
        if problem is not None:
            findings.append(f"{label}: {problem}")
        path.unlink()
    return findings


def repacked_json_swaps(doc_json: bytes, repack: Callable[[bytes], bytes], seed: int,
                        n: int = 12) -> Iterator[tuple[str, bytes]]:
    """Type swaps of a container's JSON part, each packed again by ``repack`` (valid lengths around it).

    For GLB: a swap inside the JSON chunk of the raw file only ever breaks the chunk length; repacked,
    the swap reaches the reader's JSON field checks.
    """
    for label, text in type_swaps(doc_json, np.random.default_rng(seed), n):
        yield f"JSON {label}", repack(text)


def swap_session_header(data: bytes, header_payload: bytes) -> bytes:
    """The session with its HEADER record's payload replaced (length and CRC made valid)."""
    length, _, kind = struct.unpack_from("<IIB", data, len(MAGIC))
    rest = data[len(MAGIC) + 9 + length:]
    return MAGIC + struct.pack("<IIB", len(header_payload), zlib.crc32(header_payload), kind) + header_payload + rest
