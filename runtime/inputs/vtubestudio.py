"""VTube Studio's phone tracking protocol (VTube Studio iOS/Android, MeowFace): PROTOCOLS.md §8.

The client asks the phone (UDP port 21412) for data with the JSON request
``{"messageType": "iOSTrackingDataRequest", "time": T, "sentBy": NAME, "ports": [P]}``
(:meth:`VTubeStudioAdapter.phone_request`); the phone then sends one JSON
object per frame to each listed port at the requesting IP, for ``T`` seconds
(0.5-10): the request is repeated every ``phone_every_s`` seconds, well before
``REQUEST_TIME_S`` runs out (:class:`~facepuppet.runtime.inputs.phone.PhoneRequester`).

===============  ==========================  =====================================
key              JSON type                   becomes
===============  ==========================  =====================================
``FaceFound``    bool (required)             false: tracking lost, no frame (the
                                             pipeline's tracking-loss ease takes
                                             over), counted ``face_lost``
``BlendShapes``  list of ``{"k": str,        ARKit channel ``canonical(k)``
                 "v": number}``              (PascalCase ``EyeBlinkLeft``), v as
                                             sent (0-1); other names ignored,
                                             counted ``unknown_key``
``Rotation``     ``{"x", "y", "z"}`` numbers  head rotation from degrees: x pitch,
                                             y yaw, z roll (``euler_to_quat``)
``Position``     ``{"x", "y", "z"}``          head translation, sender units
``EyeLeft``,     ``{"x", "y", "z"}``          eye angles in degrees (x pitch, y
``EyeRight``                                 yaw): fill the eyeLook* weights the
                                             frame did not carry
``Timestamp``    number, Unix ms             ``t_sender`` (seconds)
``Hotkey``       int                         kept in :attr:`VTubeStudioAdapter.hotkey`
===============  ==========================  =====================================

Other keys are ignored. Each datagram counts in exactly one of ``frames``,
``face_lost``, ``malformed``, ``oversized``, ``nonfinite`` (or
``internal_error``):

* ``oversized``: longer than ``MAX_MESSAGE`` bytes (a real frame is about 3 KB);
* ``malformed``: not UTF-8 JSON, not an object, ``FaceFound`` missing or not a
  bool, a known key of the wrong type (``BlendShapes`` not a list, an entry
  without a string ``k`` and a number ``v``, a vector without numeric x, y, z;
  booleans are not numbers), the same blendshape twice, a frame with a face
  but neither a known blendshape nor a rotation;
* ``nonfinite``: ``NaN``/``Infinity`` literals, or a number beyond float32.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.counted import Dropped, counted
from facepuppet.runtime.inputs.osc import COUNTER_NAMES, FLOAT32_MAX
from facepuppet.runtime.inputs.phone import eyes_into
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, arkit_index
from facepuppet.runtime.model.geometry import euler_to_quat

PHONE_PORT = 21412
DEFAULT_PORT = 21412  # where facepuppet listens by default (named in the request's "ports")
REQUEST_TIME_S = 3.0
REQUEST_EVERY_S = 1.0
SENT_BY = "facepuppet"
MAX_MESSAGE = 16384
COUNTERS = (*COUNTER_NAMES, "unknown_key", "face_lost")



def _reject_constant(name: str) -> float:
    raise Dropped("nonfinite")


def _num(value: object) -> float:
    if type(value) not in (int, float):  # bool is not a number here
        raise Dropped("malformed")
    if not abs(value) <= FLOAT32_MAX:
        raise Dropped("nonfinite")
    return float(value)


def _vector(obj: dict, key: str) -> tuple[float, float, float] | None:
    v = obj.get(key)
    if v is None:
        return None
    if not isinstance(v, dict):
        raise Dropped("malformed")
    try:
        return _num(v["x"]), _num(v["y"]), _num(v["z"])
    except KeyError:
        raise Dropped("malformed") from None


def vts_request(listen_port: int, time_s: float = REQUEST_TIME_S, sent_by: str = SENT_BY) -> bytes:
    """The ``iOSTrackingDataRequest`` JSON asking for ``time_s`` seconds of frames on ``listen_port``."""
    if not 0.5 <= time_s <= 10 or not 1 <= len(sent_by) <= 32 or not 0 < int(listen_port) < 65536:
        raise ValueError(f"vts_request: time 0.5-10 s, sentBy 1-32 characters and a port 1-65535 expected, got "
                         f"{time_s!r}, {sent_by!r}, {listen_port!r}")
    return json.dumps({"messageType": "iOSTrackingDataRequest", "time": time_s, "sentBy": sent_by,
                       "ports": [int(listen_port)]}).encode("ascii")


class VTubeStudioAdapter:
    """VTube Studio phone-protocol JSON frames to frames of the 52 ARKit channels with head pose (module doc)."""

    kind = "vtubestudio"
    default_port = DEFAULT_PORT
    phone_port = PHONE_PORT
    phone_every_s = REQUEST_EVERY_S

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.hotkey = -1

    @staticmethod
    def phone_request(listen_port: int) -> bytes:
        """The request naming ``listen_port`` (see :func:`vts_request`)."""
        return vts_request(listen_port)

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        """Decode one datagram received at ``t_receive`` (seconds); the frame, or None. Never raises."""
        return counted(self.counters, self._decode, data, t_receive, MAX_MESSAGE, none_counter="face_lost")

    def _decode(self, data: bytes, t: float) -> Frame | None:
        try:
            obj = json.loads(data.decode("utf-8"), parse_constant=_reject_constant)
        except (UnicodeDecodeError, ValueError, RecursionError):
            raise Dropped("malformed") from None
        if not isinstance(obj, dict):
            raise Dropped("malformed")
        found = obj.get("FaceFound")
        if type(found) is not bool:
            raise Dropped("malformed")
        shapes = obj.get("BlendShapes", [])
        if not isinstance(shapes, list):
            raise Dropped("malformed")
        rotation, position = _vector(obj, "Rotation"), _vector(obj, "Position")
        eyes = {"Left": _vector(obj, "EyeLeft"), "Right": _vector(obj, "EyeRight")}
        stamp = obj.get("Timestamp")
        t_sender = math.nan if stamp is None else _num(stamp) / 1000.0
        hotkey = obj.get("Hotkey", -1)
        if type(hotkey) is not int:
            raise Dropped("malformed")
        weights = np.full(len(ARKIT_NAMES), np.nan, dtype=np.float32)
        unknown = 0
        seen: set[str] = set()
        for entry in shapes:
            if not isinstance(entry, dict) or not isinstance(entry.get("k"), str):
                raise Dropped("malformed")
            value = _num(entry.get("v"))
            if entry["k"] in seen:
                raise Dropped("malformed")
            seen.add(entry["k"])
            index = arkit_index(entry["k"])
            if index is None:
                unknown += 1
                continue
            weights[index] = value
        self.hotkey = hotkey
        if not found:
            return None
        if not np.isfinite(weights).any() and rotation is None:
            raise Dropped("malformed")
        self.counters["unknown_key"] += unknown
        for side, angles in eyes.items():
            if angles is not None:
                eyes_into(weights, side, angles[0], angles[1])
        head = None if rotation is None else euler_to_quat(*(math.radians(a) for a in (rotation[1], rotation[0],
                                                                                        rotation[2])))
        return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights, head_rotation=head,
                     head_translation=None if position is None else np.array(position, dtype=np.float32),
                     t_sender=t_sender)


def encode_vts_frame(weights: Sequence[float], rotation: Sequence[float] = (0.0, 0.0, 0.0),
                     position: Sequence[float] = (0.0, 0.0, 0.0), eye_left: Sequence[float] = (0.0, 0.0, 0.0),
                     eye_right: Sequence[float] = (0.0, 0.0, 0.0), found: bool = True, timestamp_ms: int = 0) -> bytes:
    """A VTube Studio tracking datagram of 52 ARKit weights (Apple's order) for benchmarks and senders."""
    weights = list(weights)
    if len(weights) != 52:
        raise ValueError(f"encode_vts_frame: expected 52 weights, got {len(weights)}")

    def vec(v):
        return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}

    return json.dumps({"Timestamp": int(timestamp_ms), "Hotkey": -1, "FaceFound": bool(found),
                       "Rotation": vec(rotation), "Position": vec(position), "EyeLeft": vec(eye_left),
                       "EyeRight": vec(eye_right),
                       "BlendShapes": [{"k": n[0].upper() + n[1:], "v": float(w)}
                                       for n, w in zip(ARKIT_NAMES, weights)]}).encode("ascii")
