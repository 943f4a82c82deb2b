"""An OpenSeeFace sender written from the published layout (PROTOCOLS.md §9), independent of the decoder.

Each field is packed with :mod:`struct`, little-endian, in the order OpenSeeFace's ``facetracker.py``
writes them (one ``pack`` per field, no padding); the decoder reads them through a NumPy record dtype.
"""

from __future__ import annotations

import math
import socket
import struct

FEATURE_ORDER = (
    "eye_l", "eye_r", "eyebrow_steepness_l", "eyebrow_updown_l", "eyebrow_quirk_l",
    "eyebrow_steepness_r", "eyebrow_updown_r", "eyebrow_quirk_r", "mouth_corner_updown_l",
    "mouth_corner_inout_l", "mouth_corner_updown_r", "mouth_corner_inout_r", "mouth_open", "mouth_wide",
)
REST_QUATERNION = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # the raw pose the reference receiver calls rest
SIZE = 8 + 4 + 2 * 4 + 2 * 4 + 1 + 4 + 4 * 4 + 3 * 4 + 3 * 4 + 68 * 4 + 68 * 2 * 4 + 70 * 3 * 4 + 14 * 4


def osf_record(*, time: float = 1.7e9, face_id: int = 0, width: float = 640.0, height: float = 360.0,
               right_open: float = 1.0, left_open: float = 1.0, fit: int = 1, fit_error: float = 12.5,
               quaternion=REST_QUATERNION, euler=(180.0, 0.0, 90.0), translation=(0.5, -0.25, 6.0),
               confidence=None, landmarks=None, points=None, features: dict | None = None) -> bytes:
    """One 1785-byte face record; ``features`` by name (the others 0)."""
    feats = dict.fromkeys(FEATURE_ORDER, 0.0)
    for name, value in (features or {}).items():
        if name not in feats:
            raise KeyError(name)
        feats[name] = value
    confidence = [0.9] * 68 if confidence is None else list(confidence)
    landmarks = [(100.0 + i, 200.0 + i) for i in range(68)] if landmarks is None else list(landmarks)
    points = [(0.01 * i, -0.02 * i, 0.03) for i in range(70)] if points is None else list(points)
    out = bytearray()
    out += struct.pack("<d", time)
    out += struct.pack("<i", face_id)
    out += struct.pack("<f", width)
    out += struct.pack("<f", height)
    out += struct.pack("<f", right_open)
    out += struct.pack("<f", left_open)
    out += struct.pack("<B", fit)
    out += struct.pack("<f", fit_error)
    for q in quaternion:
        out += struct.pack("<f", q)
    for e in euler:
        out += struct.pack("<f", e)
    for t in translation:
        out += struct.pack("<f", t)
    for c in confidence:
        out += struct.pack("<f", c)
    for x, y in landmarks:
        out += struct.pack("<f", x)
        out += struct.pack("<f", y)
    for x, y, z in points:
        out += struct.pack("<f", x)
        out += struct.pack("<f", y)
        out += struct.pack("<f", z)
    for name in FEATURE_ORDER:
        out += struct.pack("<f", feats[name])
    assert len(out) == SIZE
    return bytes(out)


def float_offsets() -> list[int]:
    """Byte offsets of every float32 field of a record (the float64 time at 0 not included)."""
    return [12, 16, 20, 24] + [29 + 4 * i for i in range((SIZE - 29) // 4)]


def send_records(sock: socket.socket, address: tuple[str, int], *records: bytes) -> None:
    """One datagram holding ``records`` (as OpenSeeFace sends all faces of a video frame at once)."""
    sock.sendto(b"".join(records), address)
