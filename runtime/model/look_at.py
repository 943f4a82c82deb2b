"""VRM look-at: the gaze of the eye-look channels, through the avatar's range maps, onto eye bones or Look* expressions.

The gaze comes from the eye-look channels every tracker fills: ARKit's
``eyeLook{In,Out,Up,Down}{Left,Right}`` (any spelling
:func:`~facepuppet.runtime.mapping.channels.canonical` folds, so VMC's
perfect-sync ``EyeLookInLeft`` too). The adapters that receive eye angles
(iFacialMocap, VTube Studio, Face Cap, the phone receiver) write them into
these channels at :data:`EYE_RANGE_DEG` degrees for weight 1, so the angle is
read back at the same scale: per eye, yaw (+ toward the avatar's own left)
``= 30° · (out − in)`` for the left eye and ``30° · (in − out)`` for the right,
pitch (+ up) ``= 30° · (up − down)``.

The avatar's ``lookAt`` (VRM 1.0) or ``firstPerson.lookAt*`` (VRM 0.x) says
how far that turns its eyes (``settings["look_at"]``, written by the
importer): each of four range maps takes ``|angle| / inputMax`` (clamped to
[0, 1]), through the VRM 0.x curve when there is one (a Unity AnimationCurve,
cubic Hermite between keys), times ``outputScale``. For the **bone** type the
result is degrees of eye bone turn (inner / outer by the side each eye turns
to), for the **expression** type the weights of LookLeft / LookRight (the
outer map, both sides, as the VRM 1.0 specification says) and LookUp /
LookDown. The character faces +Z with +Y up, so a yaw turns about +Y and a
pitch up about −X.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.mapping.channels import canonical

if TYPE_CHECKING:  # for the hint only: character.py imports this module to check its table (a cycle)
    from facepuppet.runtime.model.character import Character

#: Degrees of eye turn an adapter writes as eye-look weight 1 (:mod:`facepuppet.runtime.inputs.phone`).
EYE_RANGE_DEG = 30.0
#: The eye-look channels read, in the order of :meth:`Gaze.angles`'s inputs.
GAZE_CHANNELS = ("eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeLookDownLeft",
                 "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight", "eyeLookDownRight")
MAP_NAMES = ("horizontal_inner", "horizontal_outer", "vertical_down", "vertical_up")
#: The expressions an expression-type look-at drives (VRM 0.x preset spellings, as the character names them)
LOOK_EXPRESSIONS = ("LookLeft", "LookRight", "LookUp", "LookDown")
_W = "settings.look_at"


@dataclass(frozen=True)
class RangeMap:
    """``outputScale · curve(clamp(|angle| / inputMax, 0, 1))``; no curve: the identity."""

    input_max: float
    output_scale: float
    curve: np.ndarray  # (n_keys, 4) float64: time, value, in tangent, out tangent; (0, 4) for none

    def __call__(self, angle: float) -> float:
        x = min(max(abs(angle) / self.input_max, 0.0), 1.0)
        return self.output_scale * (_hermite(self.curve, x) if len(self.curve) else x)


def _hermite(keys: np.ndarray, x: float) -> float:
    """Unity AnimationCurve evaluation: cubic Hermite between the two keys around ``x``, the end values outside."""
    if x <= keys[0, 0]:
        return float(keys[0, 1])
    if x >= keys[-1, 0]:
        return float(keys[-1, 1])
    k = int(np.searchsorted(keys[:, 0], x, side="right")) - 1
    t0, v0, _, out0 = keys[k]
    t1, v1, in1, _ = keys[k + 1]
    dt = t1 - t0
    s = (x - t0) / dt
    s2, s3 = s * s, s * s * s
    return float((2 * s3 - 3 * s2 + 1) * v0 + (s3 - 2 * s2 + s) * dt * out0 + (-2 * s3 + 3 * s2) * v1
                 + (s3 - s2) * dt * in1)


@dataclass(frozen=True)
class LookAt:
    """An avatar's look-at: its type, range maps and eye nodes.

    Attributes
    ----------
    kind : str, "bone" or "expression"
    horizontal_inner, horizontal_outer, vertical_down, vertical_up : RangeMap
    left_eye, right_eye : int, the eye bones' nodes, -1 when the avatar has none
    """

    kind: str
    horizontal_inner: RangeMap
    horizontal_outer: RangeMap
    vertical_down: RangeMap
    vertical_up: RangeMap
    left_eye: int
    right_eye: int

    def eye_turns(self, gaze: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
        """(yaw, pitch) degrees of the left and the right eye bone for a gaze from :class:`Gaze`."""
        yl, pl, yr, pr = (float(x) for x in gaze)
        left = (self.horizontal_outer(yl) if yl > 0 else -self.horizontal_inner(yl), self._pitch(pl))
        right = (self.horizontal_inner(yr) if yr > 0 else -self.horizontal_outer(yr), self._pitch(pr))
        return left, right

    def _pitch(self, pitch: float) -> float:
        return self.vertical_up(pitch) if pitch > 0 else -self.vertical_down(pitch)

    def expression_weights(self, gaze: np.ndarray) -> tuple[float, float, float, float]:
        """LookLeft, LookRight, LookUp, LookDown for a gaze (both eyes' mean), each clipped to [0, 1]."""
        yaw = 0.5 * float(gaze[0] + gaze[2])
        pitch = 0.5 * float(gaze[1] + gaze[3])
        out = (self.horizontal_outer(yaw) if yaw > 0 else 0.0, self.horizontal_outer(yaw) if yaw < 0 else 0.0,
               self.vertical_up(pitch) if pitch > 0 else 0.0, self.vertical_down(pitch) if pitch < 0 else 0.0)
        return tuple(min(max(v, 0.0), 1.0) for v in out)


class Gaze:
    """The eye angles of one channel layout: :meth:`angles` of its values, degrees.

    Attributes
    ----------
    available : bool, the layout carries some eye-look channel
    """

    def __init__(self, channels: tuple[str, ...]) -> None:
        index = {canonical(c): i for i, c in reversed(list(enumerate(channels)))}
        self._rows = np.array([index.get(c, -1) for c in GAZE_CHANNELS], np.int64)
        self.available = bool((self._rows >= 0).any())
        self._values = np.zeros(len(GAZE_CHANNELS))
        self.channels = channels

    def angles(self, weights: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(yaw left, pitch left, yaw right, pitch right) degrees, (4,) float64; a channel not sent (NaN) or
        absent counts 0."""
        v = self._values
        v[:] = 0.0
        have = self._rows >= 0
        v[have] = weights[self._rows[have]]
        np.nan_to_num(v, copy=False, nan=0.0)
        out = np.empty(4) if out is None else out
        i_l, o_l, u_l, d_l, i_r, o_r, u_r, d_r = v
        out[0] = EYE_RANGE_DEG * (o_l - i_l)
        out[1] = EYE_RANGE_DEG * (u_l - d_l)
        out[2] = EYE_RANGE_DEG * (i_r - o_r)
        out[3] = EYE_RANGE_DEG * (u_r - d_r)
        return out


def _fail(where: str, problem: str):
    raise TablesError(None, where, problem)


def _range_map(raw: Any, where: str) -> RangeMap:
    if not isinstance(raw, Mapping):
        _fail(where, "expected an object")
    vals = []
    for key, lo in (("input_max", 1e-6), ("output_scale", -np.inf)):
        v = raw.get(key)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v < lo:
            _fail(f"{where}.{key}", f"expected a finite number >= {lo}, found {v!r}")
        vals.append(float(v))
    curve = raw.get("curve", [])
    try:
        keys = np.asarray(curve, np.float64).reshape(-1, 4) if curve else np.zeros((0, 4))
    except (TypeError, ValueError):
        _fail(f"{where}.curve", "expected keys of 4 numbers")
    if len(keys) > 64 or not np.isfinite(keys).all() or np.any(np.diff(keys[:, 0]) <= 0):
        _fail(f"{where}.curve", "expected at most 64 finite keys with increasing times")
    return RangeMap(vals[0], vals[1], keys)


def look_at_of_character(character: Character) -> LookAt | None:
    """The character's look-at (None without a skeleton or look-at), checked as :func:`look_at_of` says."""
    if character.skeleton is None:
        return None
    return look_at_of(character.metadata.get("settings", {}), character.skeleton.n_nodes)


def look_at_of(settings: Mapping, n_nodes: int) -> LookAt | None:
    """The checked :class:`LookAt` of a character's ``settings`` (None when it has none); a bad field is a
    TablesError naming ``settings.look_at...``."""
    raw = settings.get("look_at")
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or raw.get("type") not in ("bone", "expression"):
        _fail(f"{_W}.type", "expected 'bone' or 'expression'")
    eyes = []
    for key in ("left_eye", "right_eye"):
        v = raw.get(key, -1)
        if not isinstance(v, int) or isinstance(v, bool) or not -1 <= v < n_nodes:
            _fail(f"{_W}.{key}", f"expected a node index or -1, found {v!r}")
        eyes.append(int(v))
    maps = {name: _range_map(raw.get(name), f"{_W}.{name}") for name in MAP_NAMES}
    return LookAt(raw["type"], **maps, left_eye=eyes[0], right_eye=eyes[1])
