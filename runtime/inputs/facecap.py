"""Face Cap (Bannaflak) live-mode OSC input: PROTOCOLS.md §3.

==============  ============  ===================================================
address         args          becomes
==============  ============  ===================================================
``/W``          ``i, f``      channel ``FACECAP_ORDER[index]`` (Face Cap's own
                              order, **not** ARKit's: index 24 is ``jawOpen``)
``/HR``         ``f x y z``   head rotation, degrees, SceneKit Euler angles (pitch
                              about x, yaw about y, roll about z; SceneKit applies
                              roll, then yaw, then pitch: q = qx · qy · qz)
``/HRQ``        ``f x y z w`` head rotation quaternion (wins over ``/HR`` in the
                              same frame)
``/HT``         ``f x y z``   head translation, sender units
``/ELR``        ``f x y``     left eye rotation, degrees (pitch x, yaw y)
``/ERR``        ``f x y``     right eye rotation, degrees
==============  ============  ===================================================

**Axes.** Face Cap's rotations are SceneKit's: right-handed, y up, the face
looking along +z towards the camera with x on the face's own left, which is
this project's frame, so quaternions are used as sent. (The Unity receiver of
§3 converts with (x, y, -z, -w) = (-x, -y, z, w): that is the z-mirror into
Unity's left-handed frame, which we do not need.)

**Eyes.** An eye rotation drives the eyeLook* channels with a small linear map:
pitch > 0 looks down, yaw > 0 turns the gaze to the face's own left (out for
the left eye, in for the right); ``EYE_RANGE_DEG`` (30°) gives weight 1,
clamped to [0, 1]. ``/W`` values for the same channels in the same frame win.

**Frame rule.** Values accumulate per frame and a frame carries only what
arrived for it (NaN elsewhere); head pose and eye rotations persist until
replaced. Whatever the bundling (one bundle a frame, a frame split over two
bundles, no bundles at all), a frame is complete

* on ``/HT`` (Face Cap sends it once per frame), or
* when a ``/W`` index comes a second time (a new frame has begun: the previous
  one is emitted first), or
* at the end of a bundle once all 52 ``/W`` indices have arrived (nothing more
  can come for that frame).

The end of a bundle alone does not end a frame: a frame split over two
bundles is emitted once, whole, not as two halves each with the other's
channels missing. The state is the adapter's own: each receiver (thread or
process) decodes with its own adapter, one per source.

At most one frame is emitted per distinct receive time; values that complete
at an already-used time go out with the next frame. A non-finite value
rejects its frame (counted once as ``nonfinite``).
"""

from __future__ import annotations

import math

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.osc import OscAdapter, all_finite, as_float, finite32, floats
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import quat_mul

#: Face Cap's blendshape index order (PROTOCOLS.md §3).
FACECAP_ORDER: tuple[str, ...] = (
    "browInnerUp", "browDownLeft", "browDownRight", "browOuterUpLeft", "browOuterUpRight",
    "eyeLookUpLeft", "eyeLookUpRight", "eyeLookDownLeft", "eyeLookDownRight", "eyeLookInLeft",
    "eyeLookInRight", "eyeLookOutLeft", "eyeLookOutRight", "eyeBlinkLeft", "eyeBlinkRight",
    "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight", "cheekPuff",
    "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "jawOpen",
    "jawForward", "jawLeft", "jawRight", "mouthFunnel", "mouthPucker",
    "mouthLeft", "mouthRight", "mouthRollUpper", "mouthRollLower", "mouthShrugUpper",
    "mouthShrugLower", "mouthClose", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft",
    "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthUpperUpLeft", "mouthUpperUpRight",
    "mouthLowerDownLeft", "mouthLowerDownRight", "mouthPressLeft", "mouthPressRight", "mouthStretchLeft",
    "mouthStretchRight", "tongueOut",
)

EYE_RANGE_DEG = 30.0

_ARKIT_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}
_TO_ARKIT = tuple(_ARKIT_INDEX[name] for name in FACECAP_ORDER)
_EYE = {  # side -> ARKit indices of (down, up, out, in)
    "Left": tuple(_ARKIT_INDEX[f"eyeLook{d}Left"] for d in ("Down", "Up", "Out", "In")),
    "Right": tuple(_ARKIT_INDEX[f"eyeLook{d}Right"] for d in ("Down", "Up", "In", "Out")),
}


def _axis_quat(axis: int, degrees: float) -> np.ndarray:
    q = np.zeros(4)
    half = math.radians(degrees) / 2
    q[axis], q[3] = math.sin(half), math.cos(half)
    return q


def scenekit_euler_to_quat(x_deg: float, y_deg: float, z_deg: float) -> np.ndarray:
    """Quaternion (x, y, z, w) float64 of SceneKit Euler angles in degrees (q = qx · qy · qz)."""
    return quat_mul(quat_mul(_axis_quat(0, x_deg), _axis_quat(1, y_deg)), _axis_quat(2, z_deg))


class FaceCapAdapter(OscAdapter):
    """Face Cap live mode: ``/W`` blendshapes, head pose, eye rotations (see module doc)."""

    kind = "facecap"
    default_port = 9000

    def __init__(self) -> None:
        super().__init__()
        n = len(ARKIT_NAMES)
        self._weights = [math.nan] * n
        self._seen = [False] * len(FACECAP_ORDER)
        self._eyes: dict[str, tuple[float, float] | None] = {"Left": None, "Right": None}
        self._euler: np.ndarray | None = None
        self._quat: np.ndarray | None = None
        self.head_rotation: np.ndarray | None = None
        self.head_translation: np.ndarray | None = None
        self._dirty = False
        self._poisoned = False
        self._is_bundle = False
        self._last_emit_t = math.nan

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        self._is_bundle = data[:8] == b"#bundle\x00"
        return super().handle(data, t_receive)

    def _message(self, address: str, params: list, t: float) -> None:
        if address == "/W":
            self._w(params, t)
        elif address == "/HT":
            v = self._vector(params, 3)
            if v is not None:
                self.head_translation = np.array(v, dtype=np.float32)
                self._dirty = True
            self._frame_ends(t)
        elif address == "/HR":
            v = self._vector(params, 3)
            if v is not None:
                self._euler = scenekit_euler_to_quat(*v)
                self._dirty = True
        elif address == "/HRQ":
            v = self._vector(params, 4)
            if v is not None:
                norm = math.hypot(*v)
                if not 1e-6 < norm < 1e30:
                    self._count("malformed")
                else:
                    self._quat = np.array(v) / norm
                    self._dirty = True
        elif address in ("/ELR", "/ERR"):
            v = self._vector(params, 2)
            if v is not None:
                self._eyes["Left" if address == "/ELR" else "Right"] = (v[0], v[1])
                self._dirty = True
        else:
            self._count("unknown_address")

    def _vector(self, params: list, n: int) -> list[float] | None:
        """n float args; None when malformed (counted) or non-finite (the frame is poisoned)."""
        values = floats(params, 0, n)
        if values is None:
            self._count("malformed")
            return None
        if not all_finite(values):
            self._poisoned = True
            return None
        return values

    def _w(self, params: list, t: float) -> None:
        if len(params) < 2 or type(params[0]) is not int:
            self._count("malformed")
            return
        value = as_float(params[1])
        index = params[0]
        if value is None or not 0 <= index < len(FACECAP_ORDER):
            self._count("malformed")
            return
        if self._seen[index]:
            self._frame_ends(t)  # the index came again: a new frame has begun
        self._seen[index] = True
        if not finite32(value):
            self._poisoned = True
            return
        self._weights[_TO_ARKIT[index]] = value
        self._dirty = True

    def _frame_ends(self, t: float) -> None:
        frame = self._complete(t)
        if frame is not None:  # None (nothing new, or the time already used) must not drop an emitted frame
            self._emit(frame)

    def _end_datagram(self, t: float) -> Frame | None:
        return self._complete(t) if self._is_bundle and all(self._seen) else None

    def _complete(self, t: float) -> Frame | None:
        """The frame accumulated so far (None if empty, poisoned or at an already-used time)."""
        if not (self._dirty or self._poisoned) or t == self._last_emit_t:
            return None
        poisoned = self._poisoned
        weights = np.array(self._weights, dtype=np.float32)
        rotation = self._quat if self._quat is not None else self._euler
        self._weights = [math.nan] * len(ARKIT_NAMES)
        self._seen = [False] * len(FACECAP_ORDER)
        self._quat = self._euler = None
        self._dirty = self._poisoned = False
        if poisoned:
            self._count("nonfinite")
            return None
        self._last_emit_t = t
        if rotation is not None:
            self.head_rotation = rotation.astype(np.float32)
        self._eyes_into(weights)
        return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights,
                     head_rotation=self.head_rotation, head_translation=self.head_translation)

    def _eyes_into(self, weights: np.ndarray) -> None:
        for side, rotation in self._eyes.items():
            if rotation is None:
                continue
            pitch, yaw = rotation[0] / EYE_RANGE_DEG, rotation[1] / EYE_RANGE_DEG
            down, up, to_left, to_right = _EYE[side]
            for index, value in ((down, pitch), (up, -pitch), (to_left, yaw), (to_right, -yaw)):
                if math.isnan(weights[index]):
                    weights[index] = min(max(value, 0.0), 1.0)
