"""VMC protocol input (VSeeFace, Warudo, VNyan, ...): OSC to ARKit-channel frames.

Facts from PROTOCOLS.md §1. Addresses handled:

==========================  ================================  ==================================
address                     args (extra ones ignored)         effect
==========================  ================================  ==================================
``/VMC/Ext/Blend/Val``      ``s name, f value``               accumulated until Apply
``/VMC/Ext/Blend/Apply``    none                              emits one Frame of the values since
                                                              the last Apply (NaN where not sent)
``/VMC/Ext/Bone/Pos``       ``s name, f px py pz qx qy qz qw``  bone ``Head``: kept, attached to
                                                              every later frame; ``LeftEye`` /
                                                              ``RightEye``: the gaze (see Eyes);
                                                              other bones ignored
``/VMC/Ext/Root/Pos``       ``s name, f px py pz qx qy qz qw``  kept in :attr:`VmcAdapter.root_position`
                                                              / :attr:`root_rotation`
``/VMC/Ext/OK``             ``i loaded [i calibState calibMode  kept in :attr:`VmcAdapter.status`
                            [i trackingStatus]]``
``/VMC/Ext/T``              ``f time``                        ``t_sender`` of later frames
``/VMC/Ext/Cam``            ``s name, f px py pz qx qy qz qw,   kept in :attr:`VmcAdapter.camera` (our
                            f fov``                           axes); drives nothing
``/VMC/Ext/Tra/Pos``        ``s serial, f px py pz qx qy qz qw``  kept in :attr:`VmcAdapter.trackers`;
``/VMC/Ext/Hmd/Pos``                                          a head tracker is the head until a
                                                              ``Head`` bone comes (see Head)
==========================  ================================  ==================================

Any other address is ignored and counted as ``unknown_address`` (receiver
rules: discard what you do not need). Too few arguments or a wrong type: the
message is dropped and counted as ``malformed``.

**Names.** Blend names are case-sensitive (``Joy`` is a VRM0 preset, ``joy``
is nothing). A name is looked up first among the VRM0 and VRM1 presets
(:data:`PRESETS`, a fixed approximation in ARKit channels), then as a perfect
sync name: any spelling that :func:`~facepuppet.runtime.mapping.channels.canonical`
brings to one of the 52 ARKit names (``JawOpen`` -> ``jawOpen``). Names that
match neither (``Neutral``, custom clips) are counted as ``unmapped_name``.
An avatar's own expressions (a character with VRM expressions, see
:mod:`facepuppet.runtime.mapping.expressions`) come as ``extra_names``: a name among
them is that channel, and a VRM preset name in its other VRM spelling (``happy``
for ``Joy``, ``blinkLeft`` for ``Blink_L``; any case) reaches the same channel;
the map then drives the expression itself instead of the ARKit approximation.
Within one frame a perfect-sync value wins over preset-derived values for the
same channel; several presets on one channel combine by maximum (a VRM1 sender
also sends the VRM0 names, so ``Joy`` and ``happy`` arrive together).

**Non-finite values.** A NaN/inf blend value poisons the frame being
accumulated: at Apply it is dropped and counted once as ``nonfinite``. A bone or
root pose with a non-finite value is ignored (the previous pose is kept) and
counted as ``nonfinite``.

**Axes.** VMC poses are Unity's: left-handed, y up, avatar facing +z, x to the
avatar's right. Ours are right-handed with x to the character's left, so a
position (x, y, z) becomes (-x, y, z) and a rotation (x, y, z, w) becomes
(x, -y, -z, w) (the mirror x -> -x). Bone poses are local (to the parent bone).

**Head.** The ``Head`` bone (its local rotation and position) is the head of
every later frame. A sender that sends no bones but names a head tracker (a
``/VMC/Ext/Tra/Pos`` serial containing ``head``, any case, or the HMD of
``/VMC/Ext/Hmd/Pos``) gives the head its rotation; the tracker's position is a
room position (metres, not an offset of the head) and stays in
:attr:`VmcAdapter.trackers`. Once a ``Head`` bone has come, trackers no longer
move the head. At most ``MAX_TRACKERS`` serials are kept; further new ones
are counted as ``unknown_address``.

**Eyes.** The ``LeftEye`` and ``RightEye`` bones (their local rotation, the
rest being the identity as in a VRM's normalised humanoid) are kept like the
head and give every later frame the eyeLook* weights its blend values did not
send: the bone's forward axis gives a yaw (+ toward the avatar's own left) and
a pitch, at :data:`~facepuppet.runtime.inputs.phone.EYE_RANGE_DEG` degrees for
weight 1, as the phone adapters write eye angles, so a look-at avatar turns its
eyes by the sender's eye bones (:mod:`facepuppet.runtime.model.look_at`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.osc import OscAdapter, all_finite, as_float, finite32, floats
from facepuppet.runtime.inputs.phone import eyes_into
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, canonical
from facepuppet.runtime.mapping.expressions import preset_of

_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}


def _both(base: str, gain: float = 1.0) -> tuple[tuple[str, float], ...]:
    return ((base + "Left", gain), (base + "Right", gain))


_BLINK = _both("eyeBlink")
_A = (("jawOpen", 1.0),)
_I = _both("mouthStretch", 0.6) + (("jawOpen", 0.15),)
_U = (("mouthPucker", 1.0),)
_E = _both("mouthStretch", 0.4) + (("jawOpen", 0.3),)
_O = (("mouthFunnel", 1.0), ("jawOpen", 0.2))
_JOY = _both("mouthSmile")
_ANGRY = _both("browDown")
_SORROW = _both("mouthFrown") + (("browInnerUp", 1.0),)
_FUN = _both("mouthSmile", 0.5)
_SURPRISED = _both("eyeWide") + (("browInnerUp", 1.0), ("jawOpen", 0.3))
_LOOK_UP = _both("eyeLookUp")
_LOOK_DOWN = _both("eyeLookDown")
# LookLeft: the character looks to its own left: left eye out, right eye in.
_LOOK_LEFT = (("eyeLookOutLeft", 1.0), ("eyeLookInRight", 1.0))
_LOOK_RIGHT = (("eyeLookInLeft", 1.0), ("eyeLookOutRight", 1.0))

#: VRM0 and VRM1 preset name -> ((ARKit channel, gain), ...); value * gain drives the channel.
PRESETS: dict[str, tuple[tuple[str, float], ...]] = {
    # VRM0 (PROTOCOLS.md §1)
    "A": _A, "I": _I, "U": _U, "E": _E, "O": _O,
    "Blink": _BLINK, "Blink_L": (("eyeBlinkLeft", 1.0),), "Blink_R": (("eyeBlinkRight", 1.0),),
    "Joy": _JOY, "Angry": _ANGRY, "Sorrow": _SORROW, "Fun": _FUN,
    "LookUp": _LOOK_UP, "LookDown": _LOOK_DOWN, "LookLeft": _LOOK_LEFT, "LookRight": _LOOK_RIGHT,
    # VRM1
    "aa": _A, "ih": _I, "ou": _U, "ee": _E, "oh": _O,
    "blink": _BLINK, "blinkLeft": (("eyeBlinkLeft", 1.0),), "blinkRight": (("eyeBlinkRight", 1.0),),
    "happy": _JOY, "angry": _ANGRY, "sad": _SORROW, "relaxed": _FUN, "surprised": _SURPRISED,
    "lookUp": _LOOK_UP, "lookDown": _LOOK_DOWN, "lookLeft": _LOOK_LEFT, "lookRight": _LOOK_RIGHT,
}

_CACHE_LIMIT = 1024  # name lookups remembered (bounded: a hostile sender can invent names)
MAX_TRACKERS = 64  # tracker serials kept (bounded for the same reason)
_TRACKERS = {"/VMC/Ext/Tra/Pos": "tracker", "/VMC/Ext/Hmd/Pos": "hmd"}


_EYE_BONES = {"LeftEye": "Left", "RightEye": "Right"}


def _gaze_angles(q: np.ndarray) -> tuple[float, float]:
    """(pitch down, yaw toward the avatar's own left), degrees, of an eye bone's rotation (x, y, z, w), our
    axes: where it turns the forward axis +Z."""
    x, y, z, w = (float(v) for v in q)
    fx, fy, fz = 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)
    return -math.degrees(math.atan2(fy, math.hypot(fx, fz))), math.degrees(math.atan2(fx, fz))


def unity_to_ours(position: Sequence[float], rotation: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Unity (left-handed, x right) position/rotation (x, y, z, w) in our axes (x left); float32."""
    px, py, pz = position
    qx, qy, qz, qw = rotation
    return (np.array([-px, py, pz], dtype=np.float32),
            np.array([qx, -qy, -qz, qw], dtype=np.float32))


class VmcAdapter(OscAdapter):
    """VMC Marionette side: blend values, head bone, root pose, status.

    Frames carry the 52 ARKit channels (``channels`` = ``ARKIT_NAMES``, then
    ``extra_names`` when given: channels matched by exact name, such as an
    elastic character's muscles),
    NaN where nothing was sent since the last Apply; the last head bone pose
    as ``head_rotation``/``head_translation`` (None until one came); the
    last ``/VMC/Ext/T`` as ``t_sender``.

    Attributes
    ----------
    root_position : ndarray of shape (3,), float32, our axes, sender units (m); or None
    root_rotation : ndarray of shape (4,), float32, (x, y, z, w); or None
    status : dict of str -> int, from ``/VMC/Ext/OK`` (loaded, calib_state, calib_mode, tracking)
    camera : dict or None, the last ``/VMC/Ext/Cam``: ``name``, ``position`` (3,), ``rotation`` (4,) in our
        axes, ``fov`` (degrees)
    trackers : dict of serial str -> (kind "tracker" or "hmd", position (3,), rotation (4,)), our axes
    head_source : str, ``none``, ``tracker`` (a head tracker) or ``bone`` (the Head bone)
    """

    kind = "vmc"
    default_port = 39539

    def __init__(self, extra_names: Iterable[str] = ()) -> None:
        super().__init__()
        self.counters["unmapped_name"] = 0
        # extra channels after the 52 ARKit ones, matched by exact name (e.g. an elastic character's muscles)
        extra = tuple(n for n in dict.fromkeys(str(n) for n in extra_names) if n not in ARKIT_NAMES)
        self.channels = ARKIT_NAMES + extra
        self._extra = {name: len(ARKIT_NAMES) + i for i, name in enumerate(extra)}
        # an extra channel named by a VRM preset also takes that preset's other spellings (Joy: happy, joy)
        self._extra_preset = {preset_of(name): i for name, i in reversed(self._extra.items())
                              if preset_of(name) is not None}
        self._direct = [math.nan] * len(self.channels)
        self._preset = [math.nan] * len(self.channels)
        self._poisoned = False
        self._lookup: dict[str, tuple[bool, tuple[tuple[int, float], ...]]] = {}
        self.head_translation: np.ndarray | None = None
        self.head_rotation: np.ndarray | None = None
        self.root_position: np.ndarray | None = None
        self.root_rotation: np.ndarray | None = None
        self.status: dict[str, int] = {}
        self.t_sender = math.nan
        self.camera: dict | None = None
        self.trackers: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        self.head_source = "none"
        self._eyes: dict[str, tuple[float, float]] = {}  # side -> (pitch down, yaw to the left), degrees

    def _message(self, address: str, params: list, t: float) -> None:
        if address == "/VMC/Ext/Blend/Val":
            self._blend_val(params)
        elif address == "/VMC/Ext/Blend/Apply":
            self._emit(self._apply(t))
        elif address == "/VMC/Ext/Bone/Pos":
            self._pose(params, root=False)
        elif address == "/VMC/Ext/Root/Pos":
            self._pose(params, root=True)
        elif address == "/VMC/Ext/OK":
            self._ok(params)
        elif address in _TRACKERS:
            self._tracker(_TRACKERS[address], params)
        elif address == "/VMC/Ext/Cam":
            self._camera(params)
        elif address == "/VMC/Ext/T":
            value = floats(params, 0, 1)
            if value is None:
                self._count("malformed")
            elif math.isfinite(value[0]):
                self.t_sender = value[0]
            else:
                self._count("nonfinite")
        else:
            self._count("unknown_address")

    def _resolve(self, name: str) -> tuple[bool, tuple[tuple[int, float], ...]]:
        """(is perfect sync, ((channel index, gain), ...)) of a blend name; empty when unmapped."""
        hit = self._lookup.get(name)
        if hit is not None:
            return hit
        if name in self._extra:
            hit = (True, ((self._extra[name], 1.0),))
        elif self._extra_preset and preset_of(name) in self._extra_preset:
            hit = (True, ((self._extra_preset[preset_of(name)], 1.0),))
        elif name in PRESETS:
            hit = (False, tuple((_INDEX[c], g) for c, g in PRESETS[name]))
        else:
            key = canonical(name)
            hit = (True, ((_INDEX[key], 1.0),)) if key in _INDEX else (False, ())
        if len(self._lookup) < _CACHE_LIMIT:
            self._lookup[name] = hit
        return hit

    def _blend_val(self, params: list) -> None:
        if len(params) < 2 or type(params[0]) is not str:
            self._count("malformed")
            return
        value = as_float(params[1])
        if value is None:
            self._count("malformed")
            return
        direct, targets = self._resolve(params[0])
        if not targets:
            self._count("unmapped_name")
            return
        if not finite32(value):
            self._poisoned = True
            return
        if direct:
            self._direct[targets[0][0]] = value
            return
        preset = self._preset
        for index, gain in targets:
            v = value * gain
            current = preset[index]
            if current != current or v > current:  # NaN (unset) or smaller
                preset[index] = v

    def _apply(self, t: float) -> Frame | None:
        direct, preset = self._direct, self._preset
        poisoned = self._poisoned
        weights = np.array(direct, dtype=np.float32)
        missing = np.isnan(weights)
        if missing.any():
            weights[missing] = np.array(preset, dtype=np.float32)[missing]
        for side, (pitch, yaw) in self._eyes.items():
            eyes_into(weights, side, pitch, yaw)
        n = len(direct)
        self._direct = [math.nan] * n
        self._preset = [math.nan] * n
        self._poisoned = False
        if poisoned:
            self._count("nonfinite")
            return None
        return Frame(
            t=t, source=self.kind, channels=self.channels, weights=weights,
            head_rotation=self.head_rotation, head_translation=self.head_translation,
            t_sender=self.t_sender,
        )

    def _named_pose(self, params: list, n_floats: int = 7) -> tuple[str, list, tuple] | None:
        """(name, the floats, (position, rotation) in our axes) of ``s name, f px py pz qx qy qz qw [...]``;
        None (counted) when malformed or not finite."""
        if not params or type(params[0]) is not str:
            self._count("malformed")
            return None
        values = floats(params, 1, n_floats)
        if values is None:
            self._count("malformed")
            return None
        if not all_finite(values):
            self._count("nonfinite")
            return None
        norm = math.hypot(*values[3:7])
        if not 1e-6 < norm < 1e30:  # not a rotation: keep the previous pose
            self._count("malformed")
            return None
        return params[0], values, unity_to_ours(values[:3], [q / norm for q in values[3:7]])

    def _pose(self, params: list, root: bool) -> None:
        if not root and params and type(params[0]) is str and params[0] in _EYE_BONES:
            pose = self._named_pose(params)
            if pose is not None:
                self._eyes[_EYE_BONES[pose[0]]] = _gaze_angles(pose[2][1])
            return
        if not root and params and type(params[0]) is str and params[0] != "Head":
            if floats(params, 1, 7) is None:
                self._count("malformed")
            return  # a bone we do not drive
        pose = self._named_pose(params)
        if pose is None:
            return
        position, rotation = pose[2]
        if root:
            self.root_position, self.root_rotation = position, rotation
        else:
            # A bone's position is its local offset from its parent bone (the neck), not a motion of the
            # head: taken as a head translation it lifted a whole VRM avatar by its neck length (1.4 m
            # at a sender's rest pose). Only the rotation turns the head.
            self.head_rotation = rotation
            self.head_source = "bone"

    def _tracker(self, kind: str, params: list) -> None:
        pose = self._named_pose(params)
        if pose is None:
            return
        serial, _, (position, rotation) = pose
        if serial not in self.trackers and len(self.trackers) >= MAX_TRACKERS:
            self._count("unknown_address")
            return
        self.trackers[serial] = (kind, position, rotation)
        if self.head_source != "bone" and (kind == "hmd" or "head" in serial.lower()):
            self.head_rotation, self.head_source = rotation, "tracker"

    def _camera(self, params: list) -> None:
        pose = self._named_pose(params, 8)
        if pose is None:
            return
        name, values, (position, rotation) = pose
        self.camera = {"name": name, "position": position, "rotation": rotation, "fov": float(values[7])}

    def _ok(self, params: list) -> None:
        if not params or any(type(p) is not int for p in params[:4]):
            self._count("malformed")
            return
        keys = ("loaded", "calib_state", "calib_mode", "tracking")
        self.status = dict(zip(keys, params[:4]))
