"""OpenSeeFace's binary UDP stream (default port 11573), decoded directly: PROTOCOLS.md §9.

One datagram holds N face records of ``RECORD_SIZE`` = 1785 bytes each, one
per tracked face, little-endian, packed without padding (the layout below):

======  =====================  ==========================================
offset  field                  encoding
======  =====================  ==========================================
0       time                   float64, the sender's Unix time, seconds
8       face id                int32
12      camera width, height   2 × float32, pixels
20      right eye open         float32, 0 (closed) … 1 (open)
24      left eye open          float32
28      3D fit succeeded       uint8, 0 or 1
29      fit error              float32
33      rotation quaternion    4 × float32 (x, y, z, w), the tracker's raw frame
49      Euler angles           3 × float32, degrees (raw frame; not used)
61      translation            3 × float32, the face model's units
73      landmark confidence    68 × float32
345     2D landmarks           68 × (float32 x, float32 y), image pixels
889     3D points              70 × 3 float32
1729    features               14 × float32 (below)
1785    end of record
======  =====================  ==========================================

Features, each about -1 … 1 with 0 at the person's running median, +1 at
the largest value seen so far, -1 at the smallest: ``eye_l``, ``eye_r``,
``eyebrow_steepness_l``, ``eyebrow_updown_l``, ``eyebrow_quirk_l``,
``eyebrow_steepness_r``, ``eyebrow_updown_r``, ``eyebrow_quirk_r``,
``mouth_corner_updown_l``, ``mouth_corner_inout_l``,
``mouth_corner_updown_r``, ``mouth_corner_inout_r``, ``mouth_open``,
``mouth_wide``. ``l``/``r`` and left/right are the person's own sides (for an
unmirrored camera).

**Mapping onto ARKit** (:func:`arkit_weights`; ``ramp(x, a, b)`` = (x - a) /
(b - a) clipped to [0, 1]; signs and dead zones read from the example VRM
driver in OpenSeeFace's repository, PROTOCOLS.md §9):

=====================================  ==============================================
channel                                from
=====================================  ==============================================
eyeBlinkLeft / Right                   ramp(1 - left / right eye open, 0.3, 2/3)
eyeWideLeft / Right                    0.7 · ramp(eye_l / eye_r, 0.5, 1)
browInnerUp                            0.8 · mean(eyebrow_updown_l, _r), clipped
browOuterUpLeft / Right                -eyebrow_steepness_l / _r, clipped
browDownLeft / Right                   -eyebrow_updown_l / _r, clipped
jawOpen                                mouth_open, clipped
mouthStretchLeft / Right               ramp(mouth_wide, 0.3, 1)
mouthPucker                            ramp(-mouth_wide, 0.3, 1)
mouthSmileLeft / Right                 ramp(mouth_corner_updown_l / _r, 0.3, 1)
mouthFrownLeft / Right                 ramp(-mouth_corner_updown_l / _r, 0.3, 1)
=====================================  ==============================================

Every other ARKit channel is NaN (not measured). The quirk and in/out
features are not mapped.

**Head.** The reference Unity receiver turns the raw quaternion (x, y, z, w)
into Unity's frame as (-y, -x, z, w) and takes the rest pose to be a 90°
roll about z (its default calibration is ``Euler(0, 0, -90)``). facepuppet
does the same, then mirrors Unity into its own axes as the VMC input does
((x, y, z, w) -> (x, -y, -z, w)): ``head_rotation`` = mirror(C · C0⁻¹) with C
the converted quaternion and C0 = (0, 0, sin 45°, cos 45°). facepuppet's own
calibration then takes the person's neutral. The translation is in the face
model's units relative to the camera (the distance included), not a head
offset: it is kept in :attr:`OpenSeeFaceAdapter.translation` and frames carry
no ``head_translation``. A record whose 3D fit failed (byte 28 = 0) carries
no pose (the sender zeroes its 3D points); its weights are used and it is
counted as ``no_fit``.

**Gaze.** The fitted 3D points 66/68 (right pupil, right eyeball centre) and
67/69 (left) give each eye's direction as the reference receiver turns them
into its eye bones: forward = mirror(swapX(centre − pupil)), which in our axes
is centre − pupil of the raw points. Its yaw (+ toward the person's own left)
and pitch fill the eyeLook* channels at
:data:`~facepuppet.runtime.inputs.phone.EYE_RANGE_DEG` degrees for weight 1,
as the phone adapters write eye angles; a record without a fit, or a pupil on
its centre, gives no gaze.

**Picking the face.** ``face_id`` None (the default, ``--face-id`` not given)
takes the first record of each datagram; an int takes the record with that
id, and a datagram without it is counted as ``other_face`` (no frame).

**Refused** (counted, no frame): a datagram over ``MAX_PACKET`` bytes
(``oversized``); empty, or a length that is not a whole number of records, or
a fit byte other than 0/1 or a fitted quaternion of length ~0 in the picked
record (``malformed``); a NaN or
infinite float anywhere in the picked record (``nonfinite``). Counters as in
:mod:`facepuppet.runtime.inputs.osc`, plus ``other_face`` and ``no_fit``.
``t_sender`` is the record's time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.counted import counted
from facepuppet.runtime.inputs.osc import COUNTER_NAMES
from facepuppet.runtime.inputs.phone import eyes_into
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import quat_mul

N_POINTS = 68
N_POINTS_3D = 70
FEATURES: tuple[str, ...] = (
    "eye_l", "eye_r", "eyebrow_steepness_l", "eyebrow_updown_l", "eyebrow_quirk_l",
    "eyebrow_steepness_r", "eyebrow_updown_r", "eyebrow_quirk_r", "mouth_corner_updown_l",
    "mouth_corner_inout_l", "mouth_corner_updown_r", "mouth_corner_inout_r", "mouth_open", "mouth_wide",
)
RECORD = np.dtype([
    ("time", "<f8"), ("id", "<i4"), ("camera", "<f4", (2,)), ("right_open", "<f4"), ("left_open", "<f4"),
    ("fit_ok", "u1"), ("fit_error", "<f4"), ("quaternion", "<f4", (4,)), ("euler", "<f4", (3,)),
    ("translation", "<f4", (3,)), ("confidence", "<f4", (N_POINTS,)), ("landmarks", "<f4", (N_POINTS, 2)),
    ("points3d", "<f4", (N_POINTS_3D, 3)), ("features", "<f4", (len(FEATURES),)),
])
RECORD_SIZE = RECORD.itemsize  # 1785
MAX_FACES = 36  # 36 records is the most one IPv4 UDP datagram (65,507 bytes) can hold
MAX_PACKET = MAX_FACES * RECORD_SIZE
EXTRA_COUNTERS = ("other_face", "no_fit")

_F = {name: i for i, name in enumerate(FEATURES)}
_I = {name: i for i, name in enumerate(ARKIT_NAMES)}
REST_QUATERNION = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))  # raw C0: the reference receiver's rest pose
_REST = np.array(REST_QUATERNION)
_REST_INV = _REST * np.array([-1.0, -1.0, -1.0, 1.0])
#: (offset, length) of the float32 runs of a record: camera .. left_open, fit_error, quaternion .. features
_FLOAT_RUNS = ((12, 16), (29, 4), (33, RECORD_SIZE - 33))


def _ramp(x: float, a: float, b: float) -> float:
    v = (x - a) / (b - a)
    return 0.0 if v <= 0.0 else 1.0 if v >= 1.0 else v


def _clip(x: float) -> float:
    return 0.0 if x <= 0.0 else 1.0 if x >= 1.0 else x


def arkit_weights(features: Sequence[float], right_open: float, left_open: float) -> np.ndarray:
    """The 52 ARKit weights (float32, NaN where OpenSeeFace measures nothing) of one record.

    Parameters
    ----------
    features : sequence of 14 float, in :data:`FEATURES` order
    right_open, left_open : float, the record's eye openness (0 closed … 1 open)
    """
    f = [float(v) for v in features]
    w = np.full(len(ARKIT_NAMES), np.nan, dtype=np.float32)
    updown_l, updown_r = f[_F["eyebrow_updown_l"]], f[_F["eyebrow_updown_r"]]
    wide = f[_F["mouth_wide"]]
    for side, s in (("Left", "l"), ("Right", "r")):
        is_open = left_open if s == "l" else right_open
        eye = f[_F[f"eye_{s}"]]
        updown = f[_F[f"eyebrow_updown_{s}"]]
        corner = f[_F[f"mouth_corner_updown_{s}"]]
        w[_I["eyeBlink" + side]] = _ramp(1.0 - is_open, 0.3, 2.0 / 3.0)
        w[_I["eyeWide" + side]] = 0.7 * _ramp(eye, 0.5, 1.0)
        w[_I["browOuterUp" + side]] = _clip(-f[_F[f"eyebrow_steepness_{s}"]])
        w[_I["browDown" + side]] = _clip(-updown)
        w[_I["mouthStretch" + side]] = _ramp(wide, 0.3, 1.0)
        w[_I["mouthSmile" + side]] = _ramp(corner, 0.3, 1.0)
        w[_I["mouthFrown" + side]] = _ramp(-corner, 0.3, 1.0)
    w[_I["browInnerUp"]] = _clip(0.8 * 0.5 * (updown_l + updown_r))
    w[_I["jawOpen"]] = _clip(f[_F["mouth_open"]])
    w[_I["mouthPucker"]] = _ramp(-wide, 0.3, 1.0)
    return w


def gaze_angles(forward: Sequence[float]) -> tuple[float, float] | None:
    """(pitch down, yaw toward the person's own left), degrees, of an eye's forward direction in our axes (x to
    the person's left, y up, z out of the face); None for a zero vector."""
    x, y, z = (float(v) for v in forward)
    if math.hypot(x, y, z) < 1e-9:
        return None
    return -math.degrees(math.atan2(y, math.hypot(x, z))), math.degrees(math.atan2(x, z))


def head_rotation(quaternion: Sequence[float]) -> np.ndarray | None:
    """facepuppet's head rotation (x, y, z, w) float32 from a record's raw quaternion; None if it is ~0."""
    x, y, z, w = (float(v) for v in quaternion)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not 1e-6 < norm < 1e30:
        return None
    unity = np.array([-y, -x, z, w]) / norm  # the reference receiver's conversion into Unity's frame
    rel = quat_mul(unity, _REST_INV)
    return np.array([rel[0], -rel[1], -rel[2], rel[3]], dtype=np.float32)  # Unity -> ours (mirror x)


class OpenSeeFaceAdapter:
    """OpenSeeFace UDP datagrams to frames of the 52 ARKit channels (see the module doc for the mapping).

    Parameters
    ----------
    face_id : int or None, the face to follow (None: the first record of each datagram)

    Attributes
    ----------
    translation : ndarray of shape (3,), float32, the last picked record's raw translation; or None
    camera : (width, height) of the last picked record, pixels; or None
    faces_seen : int, records in the last well-formed datagram
    """

    kind = "openseeface"
    default_port = 11573

    def __init__(self, face_id: int | None = None) -> None:
        self.face_id = None if face_id is None else int(face_id)
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES + EXTRA_COUNTERS, 0)
        self.translation: np.ndarray | None = None
        self.camera: tuple[float, float] | None = None
        self.faces_seen = 0

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        """Decode one datagram received at ``t_receive`` (seconds); the frame, or None. Never raises."""
        return counted(self.counters, self._decode, data, t_receive)

    def _pick(self, data: bytes, n: int) -> int | None:
        if self.face_id is None:
            return 0
        want = self.face_id
        for k in range(n):
            if int.from_bytes(data[k * RECORD_SIZE + 8:k * RECORD_SIZE + 12], "little", signed=True) == want:
                return k
        return None

    def _decode(self, data: bytes, t: float) -> Frame | None:
        counters = self.counters
        size = len(data)
        if size > MAX_PACKET:
            counters["oversized"] += 1
            return None
        n, rest = divmod(size, RECORD_SIZE)
        if n == 0 or rest:
            counters["malformed"] += 1
            return None
        self.faces_seen = n
        k = self._pick(data, n)
        if k is None:
            counters["other_face"] += 1
            return None
        start = k * RECORD_SIZE
        fit = data[start + 28]
        if fit > 1:
            counters["malformed"] += 1
            return None
        time = float(np.frombuffer(data, "<f8", 1, start)[0])
        if not math.isfinite(time) or not all(
                np.isfinite(np.frombuffer(data, "<f4", length // 4, start + at)).all() for at, length in _FLOAT_RUNS):
            counters["nonfinite"] += 1
            return None
        rec = np.frombuffer(data, RECORD, 1, start)[0]
        rotation = None
        if fit:
            rotation = head_rotation(rec["quaternion"])
            if rotation is None:  # a fitted pose that is no rotation
                counters["malformed"] += 1
                return None
        else:
            counters["no_fit"] += 1
        self.translation = np.array(rec["translation"], dtype=np.float32)
        self.camera = (float(rec["camera"][0]), float(rec["camera"][1]))
        weights = arkit_weights(rec["features"], float(rec["right_open"]), float(rec["left_open"]))
        if fit:
            points = rec["points3d"]
            for side, pupil, centre in (("Right", 66, 68), ("Left", 67, 69)):
                angles = gaze_angles(points[centre] - points[pupil])
                if angles is not None:
                    eyes_into(weights, side, *angles)
        return Frame(t=t, source=self.kind, channels=ARKIT_NAMES, weights=weights, head_rotation=rotation,
                     t_sender=float(time))


def encode_record(*, time: float = 0.0, face_id: int = 0, camera: tuple[float, float] = (640.0, 360.0),
                  right_open: float = 1.0, left_open: float = 1.0, fit: int = 1, fit_error: float = 0.0,
                  quaternion: Sequence[float] = REST_QUATERNION, euler: Sequence[float] = (180.0, 0.0, 90.0),
                  translation: Sequence[float] = (0.0, 0.0, 0.0), features: Sequence[float] = (0.0,) * 14,
                  confidence: Sequence[float] | None = None, landmarks: Sequence | None = None,
                  points: Sequence | None = None) -> bytes:
    """One face record in the layout above (for benchmarks and senders; the tests use their own sender).

    Parameters
    ----------
    features : 14 float in :data:`FEATURES` order
    confidence : 68 float or None (zeros); landmarks : (68, 2) or None; points : (70, 3) or None
    """
    rec = np.zeros(1, dtype=RECORD)
    r = rec[0]
    r["time"], r["id"], r["camera"] = time, face_id, camera
    r["right_open"], r["left_open"], r["fit_ok"], r["fit_error"] = right_open, left_open, fit, fit_error
    r["quaternion"], r["euler"], r["translation"], r["features"] = quaternion, euler, translation, features
    if confidence is not None:
        r["confidence"] = confidence
    if landmarks is not None:
        r["landmarks"] = landmarks
    if points is not None:
        r["points3d"] = points
    return rec.tobytes()
