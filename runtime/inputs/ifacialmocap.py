"""iFacialMocap's UDP text stream (default port 49983): PROTOCOLS.md §7.

One datagram is one frame, UTF-8 text, items separated by ``|``:

====================================  ==============================================
item                                  becomes
====================================  ==============================================
``name-value`` (v1), ``name&value``   the ARKit channel ``canonical(name)`` (``eyeBlink_L``
(v2; the value may be negative)       -> ``eyeBlinkLeft``), value / 100 (0-100 -> 0-1)
``=head#rx,ry,rz,tx,ty,tz``           head rotation from degrees (rx pitch about x, ry yaw
(``head#`` accepted too)              about y, rz roll about z: ``euler_to_quat``), head
                                      translation (tx, ty, tz, sender units)
``rightEye#rx,ry,rz``,                eye rotation in degrees: fills the eyeLook* weights
``leftEye#rx,ry,rz``                  of that eye that the datagram did not carry
                                      (:func:`~facepuppet.runtime.inputs.phone.eyes_into`)
====================================  ==============================================

Each item is read on its own, so v1 and v2 items may even be mixed. A name
that is not one of the 52 ARKit shapes (stray keys such as ``hapihapi-0``) is
ignored and counted once per item in ``unknown_key``. Channels the datagram
does not carry are NaN (not sent); head pose and eye angles are per datagram.

Each datagram counts in exactly one of ``frames``, ``malformed``,
``oversized``, ``nonfinite`` (or ``internal_error``):

* ``oversized``: longer than ``MAX_PACKET`` bytes (real ones are about 1 KB);
* ``malformed``: not UTF-8; an item that is neither a key/value pair nor a
  ``head#``/``…Eye#`` item; a value that is not a number; a head item without
  6 numbers or an eye item without 3; the same name or item twice; no known
  channel and no head pose at all (nothing to draw);
* ``nonfinite``: a value, angle or translation that is NaN, infinite or
  beyond float32 (the frame is dropped, not half drawn).

Facemotion3D (same family, ``FM_*`` keys) and the developer's binary "v3" protocol are not read: PROTOCOLS.md §7.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.counted import Dropped, counted
from facepuppet.runtime.inputs.osc import COUNTER_NAMES, FLOAT32_MAX
from facepuppet.runtime.inputs.phone import eyes_into
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, arkit_index
from facepuppet.runtime.model.geometry import euler_to_quat

#: the start payload (iFacialMocap's developer page); ``|sendDataVersion=v2`` asks for the v2 frames
START = "iFacialMocap_sahuasouryya9218sauhuiayeta91555dy3719"
START_V2 = START + "|sendDataVersion=v2"
PORT = 49983
MAX_PACKET = 8192
COUNTERS = (*COUNTER_NAMES, "unknown_key")

_EYES = {"rightEye": "Right", "leftEye": "Left"}


def _number(text: str) -> float:
    """A float of an item's value text; Dropped("malformed") for anything else, Dropped("nonfinite") for NaN/inf."""
    text = text.strip()
    if not text or text.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        raise Dropped("nonfinite" if text else "malformed")
    try:
        value = float(text)
    except ValueError:
        raise Dropped("malformed") from None
    if not abs(value) <= FLOAT32_MAX:
        raise Dropped("nonfinite")
    return value


def _numbers(text: str, n: int) -> list[float]:
    parts = text.split(",")
    if len(parts) != n:
        raise Dropped("malformed")
    return [_number(p) for p in parts]


class IFacialMocapAdapter:
    """iFacialMocap v1/v2 datagrams to frames of the 52 ARKit channels with head pose (see module doc)."""

    kind = "ifacialmocap"
    default_port = PORT
    phone_port = PORT
    phone_every_s = 3.0  # the start payload again every 3 s: a phone app started after facepuppet still begins

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        #: the last eye angles seen, degrees (pitch, yaw, roll), per side
        self.eyes: dict[str, tuple[float, float, float] | None] = {"Left": None, "Right": None}

    @staticmethod
    def phone_request(listen_port: int) -> bytes:
        """The start payload (v2 frames; the phone answers on port 49983 whatever ``listen_port`` is)."""
        return START_V2.encode("ascii")

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        """Decode one datagram received at ``t_receive`` (seconds); the frame, or None. Never raises."""
        return counted(self.counters, self._decode, data, t_receive, MAX_PACKET)

    def _decode(self, data: bytes, t: float) -> Frame:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise Dropped("malformed") from None
        weights = np.full(len(ARKIT_NAMES), np.nan, dtype=np.float32)
        seen: set[str] = set()
        head = None
        eyes: dict[str, list[float]] = {}
        unknown = 0
        for item in text.split("|"):
            item = item.strip()
            if not item:
                continue
            if "#" in item:
                name, _, values = item.partition("#")
                name = name.lstrip("=")
                if name in seen:
                    raise Dropped("malformed")
                seen.add(name)
                if name == "head":
                    head = _numbers(values, 6)
                elif name in _EYES:
                    eyes[_EYES[name]] = _numbers(values, 3)
                else:
                    raise Dropped("malformed")
                continue
            if "&" in item:
                name, _, value = item.partition("&")
            elif "-" in item:
                name, _, value = item.partition("-")
            else:
                raise Dropped("malformed")
            name = name.strip()
            if not name or name in seen:
                raise Dropped("malformed")
            seen.add(name)
            number = _number(value)
            index = arkit_index(name)
            if index is None:
                unknown += 1
                continue
            weights[index] = number / 100.0
        known = bool(np.isfinite(weights).any())
        if not known and head is None:
            raise Dropped("malformed")
        self.counters["unknown_key"] += unknown
        rotation = translation = None
        if head is not None:
            rx, ry, rz, tx, ty, tz = head
            rotation = euler_to_quat(math.radians(ry), math.radians(rx), math.radians(rz))
            translation = np.array((tx, ty, tz), dtype=np.float32)
        for side, (ex, ey, ez) in eyes.items():
            self.eyes[side] = (ex, ey, ez)
            eyes_into(weights, side, ex, ey)
        return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights, head_rotation=rotation,
                     head_translation=translation)


def _wire_name(name: str) -> str:
    """iFacialMocap's spelling of an ARKit name (``eyeBlinkLeft`` -> ``eyeBlink_L``; jawLeft etc. kept)."""
    if name in ("jawLeft", "jawRight", "mouthLeft", "mouthRight"):
        return name
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side):
            return name[:-len(side)] + suffix
    return name


def encode_ifm_frame(weights: Sequence[float], head: Sequence[float] = (0.0,) * 6,
                     right_eye: Sequence[float] = (0.0,) * 3, left_eye: Sequence[float] = (0.0,) * 3,
                     version: int = 2) -> bytes:
    """An iFacialMocap datagram of 52 ARKit weights (0-1, Apple's order) for benchmarks and senders.

    ``head`` is (rx, ry, rz degrees, tx, ty, tz); the eyes (rx, ry, rz) degrees; v1 values are rounded
    to integers 0-100 as the app sends them, v2 keep two decimals.
    """
    weights = list(weights)
    if len(weights) != 52 or len(head) != 6 or len(right_eye) != 3 or len(left_eye) != 3:
        raise ValueError("encode_ifm_frame: expected 52 weights, 6 head values and 3 per eye")
    if version == 1:
        items = [f"{_wire_name(n)}-{max(0, min(100, round(100 * w)))}" for n, w in zip(ARKIT_NAMES, weights)]
    else:
        items = [f"{_wire_name(n)}&{100 * w:.2f}" for n, w in zip(ARKIT_NAMES, weights)]
    items.append("=head#" + ",".join(f"{x:.4f}" for x in head))
    items.append("rightEye#" + ",".join(f"{x:.4f}" for x in right_eye))
    items.append("leftEye#" + ",".join(f"{x:.4f}" for x in left_eye))
    return ("|".join(items) + "|").encode("ascii")
