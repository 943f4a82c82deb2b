"""Live Link Face's binary UDP stream (default port 11111), decoded directly: PROTOCOLS.md §5.

Version-6 packet, ``L = len(name)``:

=========  ==========================  =========================================
offset     field                       encoding
=========  ==========================  =========================================
0          version                     int32 little-endian, = 6
4          device id                   37 bytes, starting with ``$``
41         name length L               int32 big-endian
45         name                        L bytes UTF-8
45+L       frame number, sub-frame,    int32, float32, int32, int32 big-endian
           fps, denominator
61+L       value count                 uint8, = 61
62+L       values                      61 × float32 big-endian
306+L      end
=========  ==========================  =========================================

The 61 values are the 52 ARKit weights in Apple's order
(:data:`~facepuppet.runtime.mapping.channels.ARKIT_NAMES`), then head yaw, pitch, roll
(radians, to ``head_rotation`` via
:func:`~facepuppet.runtime.model.geometry.euler_to_quat`, as for the CSV in
:mod:`facepuppet.runtime.recording.livelinkface_csv`), then left- and right-eye yaw, pitch, roll (not
used: the eyeLook* weights carry gaze).

The version field is checked first: any version but 6 is ``malformed`` (the
older engine layout has a 1-byte version and a 16-byte FrameTime and is not
read). Also ``malformed``: a device id not starting with ``$``, a negative or
too long name length, a count other than 61, a packet shorter or longer than
its fields. Over ``MAX_PACKET`` bytes: ``oversized``. A non-finite value:
``nonfinite``. Counters as in :mod:`facepuppet.runtime.inputs.osc`.

``number`` is the frame number; ``t_sender`` = (frame + sub-frame) ·
denominator / fps seconds when fps > 0, else NaN.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.counted import counted
from facepuppet.runtime.inputs.osc import COUNTER_NAMES
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

VERSION = 6
N_VALUES = 61
MAX_PACKET = 4096
_HEAD = struct.Struct(">i")
_TIMING = struct.Struct(">ifiiB")
_VALUES = struct.Struct(f">{N_VALUES}f")
_FIXED = 45 + _TIMING.size + _VALUES.size  # 306 bytes besides the name


class LiveLinkFaceAdapter:
    """Live Link Face UDP packets to frames of the 52 ARKit channels with head rotation."""

    kind = "livelinkface"
    default_port = 11111

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.device_name = ""

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        """Decode one packet received at ``t_receive`` (seconds); the frame, or None. Never raises."""
        return counted(self.counters, self._decode, data, t_receive)

    def _decode(self, data: bytes, t: float) -> Frame | None:
        counters = self.counters
        if len(data) > MAX_PACKET:
            counters["oversized"] += 1
            return None
        if len(data) < _FIXED or int.from_bytes(data[0:4], "little", signed=True) != VERSION \
                or data[4:5] != b"$":
            counters["malformed"] += 1
            return None
        (name_len,) = _HEAD.unpack_from(data, 41)
        if name_len < 0 or len(data) != _FIXED + name_len:
            counters["malformed"] += 1
            return None
        end = 45 + name_len
        number, sub_frame, fps, denominator, count = _TIMING.unpack_from(data, end)
        if count != N_VALUES:
            counters["malformed"] += 1
            return None
        values = _VALUES.unpack_from(data, end + _TIMING.size)
        if not all(math.isfinite(v) for v in values) or not math.isfinite(sub_frame):
            counters["nonfinite"] += 1
            return None
        self.device_name = data[45:end].decode("utf-8", errors="replace")
        yaw, pitch, roll = values[52:55]
        t_sender = (number + sub_frame) * denominator / fps if fps > 0 and denominator > 0 else math.nan
        return Frame(
            t=t, source=self.kind, channels=ARKIT_NAMES,
            weights=np.array(values[:52], dtype=np.float32),
            head_rotation=euler_to_quat(yaw, pitch, roll), t_sender=t_sender, number=number,
        )


def encode_llf_packet(weights: Sequence[float], head: Sequence[float] = (0.0, 0.0, 0.0),
                      eyes: Sequence[float] = (0.0,) * 6, number: int = 0, sub_frame: float = 0.0, fps: int = 60,
                      denominator: int = 1, name: str = "iPhone",
                      device_id: str = "$00000000-0000-0000-0000-000000000000") -> bytes:
    """A Live Link Face version-6 UDP packet (the layout above), for tests, benchmarks and senders.

    Parameters
    ----------
    weights : sequence of 52 float, ARKit order
    head : (yaw, pitch, roll) radians
    eyes : 6 float, left then right eye yaw, pitch, roll
    """
    weights = list(weights)
    if len(weights) != 52 or len(head) != 3 or len(eyes) != 6:
        raise ValueError(f"encode_llf_packet: expected 52 weights, 3 head and 6 eye values, got "
                         f"{len(weights)}, {len(head)}, {len(eyes)}")
    uid = device_id.encode("ascii")[:37].ljust(37, b"\0")
    raw_name = name.encode("utf-8")
    return b"".join((
        struct.pack("<i", VERSION), uid, _HEAD.pack(len(raw_name)), raw_name,
        _TIMING.pack(number, sub_frame, fps, denominator, N_VALUES),
        _VALUES.pack(*weights, *head, *eyes),
    ))
