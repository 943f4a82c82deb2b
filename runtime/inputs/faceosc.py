"""FaceOSC (ofxFaceTracker) input: PROTOCOLS.md §4, one bundle per frame -> one Frame.

==========================  =========  =========================================
address                     args       becomes
==========================  =========  =========================================
``/found``                  ``i``      0: the frame has all-NaN weights, no pose
``/pose/orientation``       ``f x y z`` head rotation (radians, see Axes)
``/pose/position``          ``f x y``  kept in :attr:`FaceOscAdapter.pose_position`
``/pose/scale``             ``f``      kept in :attr:`FaceOscAdapter.pose_scale`
``/gesture/mouth/height``   ``f``      jawOpen (max with ``/gesture/jaw``)
``/gesture/jaw``            ``f``      jawOpen
``/gesture/mouth/width``    ``f``      wider: mouthSmile L/R (and 0.3x mouthStretch
                                       L/R); narrower: mouthPucker
``/gesture/eyebrow/left``   ``f``      up: browOuterUp (that side) and browInnerUp
``/gesture/eyebrow/right``             (mean of both); down: browDown (that side)
``/gesture/eye/left|right`` ``f``      eyeBlink (openness, inverted)
``/gesture/nostrils``       ``f``      accepted, drives nothing
``/raw``                    132 ``f``  ``markers`` (66, 3): (x, y, 0) image points
==========================  =========  =========================================

**Calibration-free normalisation.** FaceOSC gestures are distances in the
tracker's face-scale units with a resting value that differs per person. Each
gesture keeps a running neutral ``n`` that follows the value fast (time
constant ``TAU_REST`` = 0.5 s) towards its rest side (down for mouth height,
jaw and nostrils; up for eye openness) and slowly
(``TAU_ACTIVE`` = 20 s) the other way, so a held expression fades only over
tens of seconds; two-sided gestures (mouth width, eyebrows) use a symmetric
``TAU_MID`` = 10 s. The first value seen is the neutral. The weight is the
distance from the neutral over a fixed span (:data:`SPANS`, typical FaceOSC
travel from rest to full expression), clamped to [0, 1]. A value more than
``RESET_SPANS`` spans from the neutral (a tracking glitch, another face)
restarts the neutral there. Time is the frames'
receive time, so a replay reproduces the live weights.

**Sides and axes.** ofxFaceTracker's left/right are image sides: its left eye
(landmarks 36-41) is the subject's right in an unmirrored camera image, so
FaceOSC ``left`` drives our ``Right`` channels (``mirrored=True`` swaps back for
a mirrored camera). ``/pose/orientation`` is (pitch, yaw, roll) in OpenCV
camera axes (y down, z into the scene); ours are y up, z towards the camera,
so yaw and roll change sign: ``euler_to_quat(-yaw, pitch, -roll)``.
Frames are emitted at the end of each datagram that carried a FaceOSC message.
"""

from __future__ import annotations

import math

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.osc import OscAdapter, all_finite, floats
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

TAU_REST = 0.5
TAU_ACTIVE = 20.0
TAU_MID = 10.0
RESET_SPANS = 10.0  # a jump this many spans from the neutral restarts it (glitch or new person)
#: Gesture -> span (FaceOSC units) from neutral to weight 1.
SPANS: dict[str, float] = {
    "mouth_height": 4.0, "jaw": 4.0, "mouth_width": 2.0, "eyebrow_left": 1.0, "eyebrow_right": 1.0,
    "eye_left": 0.8, "eye_right": 0.8, "nostrils": 1.0,
}
N_RAW = 66

_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}
_GESTURES = {  # address -> (gesture key, rest side: "low", "high" or "mid")
    "/gesture/mouth/height": ("mouth_height", "low"),
    "/gesture/jaw": ("jaw", "low"),
    "/gesture/mouth/width": ("mouth_width", "mid"),
    "/gesture/eyebrow/left": ("eyebrow_left", "mid"),
    "/gesture/eyebrow/right": ("eyebrow_right", "mid"),
    "/gesture/eye/left": ("eye_left", "high"),
    "/gesture/eye/right": ("eye_right", "high"),
    "/gesture/nostrils": ("nostrils", "low"),
}
_POSE = {"/pose/orientation": 3, "/pose/position": 2, "/pose/scale": 1}


class RunningNeutral:
    """Neutral value of one gesture, following fast towards rest and slowly away from it.

    Parameters
    ----------
    rest : "low", "high" or "mid", the side the gesture rests on
    """

    def __init__(self, rest: str, span: float) -> None:
        self.rest = rest
        self.span = span
        self.value = math.nan

    def update(self, x: float, dt: float) -> float:
        """New neutral after value ``x`` arrived ``dt`` seconds after the previous one."""
        if math.isnan(self.value) or abs(x - self.value) > RESET_SPANS * self.span:
            self.value = x
            return x
        if self.rest == "mid":
            tau = TAU_MID
        else:
            towards_rest = x < self.value if self.rest == "low" else x > self.value
            tau = TAU_REST if towards_rest else TAU_ACTIVE
        self.value += (x - self.value) * (1.0 - math.exp(-max(dt, 0.0) / tau))
        return self.value


def _clip01(v: float) -> float:
    return min(max(v, 0.0), 1.0)


class FaceOscAdapter(OscAdapter):
    """FaceOSC gestures, pose and raw points to ARKit channels (see module doc).

    Parameters
    ----------
    mirrored : bool, True when the camera image FaceOSC tracks is mirrored
    """

    kind = "faceosc"
    default_port = 8338

    def __init__(self, mirrored: bool = False) -> None:
        super().__init__()
        self.mirrored = mirrored
        self._neutral = {key: RunningNeutral(rest, SPANS[key]) for key, rest in _GESTURES.values()}
        self._last_t = math.nan
        self.pose_position: tuple[float, float] | None = None
        self.pose_scale = math.nan
        self._reset()

    def _reset(self) -> None:
        self._gestures: dict[str, float] = {}
        self._found: int | None = None
        self._rotation: np.ndarray | None = None
        self._raw: np.ndarray | None = None
        self._any = False
        self._poisoned = False

    def _message(self, address: str, params: list, t: float) -> None:
        if address == "/found":
            if not params or type(params[0]) is not int:
                self._count("malformed")
                return
            self._found = params[0]
            self._any = True
        elif address in _GESTURES:
            value = self._floats(params, 1)
            if value is not None:
                self._gestures[_GESTURES[address][0]] = value[0]
        elif address in _POSE:
            value = self._floats(params, _POSE[address])
            if value is None:
                return
            if address == "/pose/orientation":
                pitch, yaw, roll = value
                self._rotation = euler_to_quat(-yaw, pitch, -roll).astype(np.float32)
            elif address == "/pose/position":
                self.pose_position = (value[0], value[1])
            else:
                self.pose_scale = value[0]
        elif address == "/raw":
            value = self._floats(params, 2 * N_RAW)
            if value is not None:
                raw = np.zeros((N_RAW, 3), dtype=np.float32)
                raw[:, :2] = np.asarray(value, dtype=np.float32).reshape(N_RAW, 2)
                self._raw = raw
        else:
            self._count("unknown_address")

    def _floats(self, params: list, n: int) -> list[float] | None:
        values = floats(params, 0, n)
        if values is None:
            self._count("malformed")
            return None
        self._any = True
        if not all_finite(values):
            self._poisoned = True
            return None
        return values

    def _end_datagram(self, t: float) -> Frame | None:
        if not self._any:
            return None
        found, gestures, rotation, raw = self._found, self._gestures, self._rotation, self._raw
        poisoned = self._poisoned
        self._reset()
        if poisoned:
            self._count("nonfinite")
            return None
        dt = 0.0 if math.isnan(self._last_t) else t - self._last_t
        self._last_t = t
        weights = np.full(len(ARKIT_NAMES), np.nan, dtype=np.float32)
        if found == 0:
            return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights)
        self._weights_into(weights, gestures, dt)
        names = tuple(f"faceosc_{i}" for i in range(N_RAW)) if raw is not None else None
        return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights,
                     head_rotation=rotation, markers=raw, marker_names=names)

    def _delta(self, gestures: dict[str, float], key: str, dt: float) -> float | None:
        """Signed distance from the running neutral over the gesture's span; None when not sent."""
        x = gestures.get(key)
        if x is None:
            return None
        neutral = self._neutral[key].update(x, dt)
        return (x - neutral) / SPANS[key]

    def _weights_into(self, w: np.ndarray, gestures: dict[str, float], dt: float) -> None:
        d = {key: self._delta(gestures, key, dt) for key in SPANS}
        opens = [_clip01(v) for v in (d["mouth_height"], d["jaw"]) if v is not None]
        if opens:
            w[_INDEX["jawOpen"]] = max(opens)
        if d["mouth_width"] is not None:
            wider = _clip01(d["mouth_width"])
            for side in ("Left", "Right"):
                w[_INDEX["mouthSmile" + side]] = wider
                w[_INDEX["mouthStretch" + side]] = 0.3 * wider
            w[_INDEX["mouthPucker"]] = _clip01(-d["mouth_width"])
        # FaceOSC's left is the image's left: the subject's right unless mirrored.
        sides = {"left": "Left" if self.mirrored else "Right", "right": "Right" if self.mirrored else "Left"}
        ups = []
        for osc_side, side in sides.items():
            brow = d["eyebrow_" + osc_side]
            if brow is not None:
                ups.append(_clip01(brow))
                w[_INDEX["browOuterUp" + side]] = _clip01(brow)
                w[_INDEX["browDown" + side]] = _clip01(-brow)
            eye = d["eye_" + osc_side]
            if eye is not None:
                w[_INDEX["eyeBlink" + side]] = _clip01(-eye)
        if ups:
            w[_INDEX["browInnerUp"]] = sum(ups) / len(ups)
