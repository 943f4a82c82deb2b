"""VRM look-at read into the character: which way the eyes turn and how far, ``settings["look_at"]``.

VRM 1.0 ``lookAt`` (``type`` "bone" or "expression", ``rangeMapHorizontalInner``,
``…Outer``, ``rangeMapVerticalDown``, ``…Up``: each ``inputMaxValue`` degrees of
gaze give ``outputScale``, degrees of eye bone turn or an expression weight) and
VRM 0.x ``firstPerson.lookAtTypeName`` ("Bone" or "BlendShape") with its
``lookAtHorizontalInner`` … degree maps (``xRange``, ``yRange`` and a Unity
``curve``: keys of time, value, in tangent, out tangent, flat). Defaults are
those of the VRM 1.0 schema (input 90°, output 10° for bones, 1 for
expressions). The runtime (:mod:`facepuppet.runtime.model.look_at`) applies
them; the maps are bounded (a curve has at most :data:`MAX_CURVE_KEYS` keys,
times increasing) and refused by their JSON path when malformed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.read_state import ReadState

MAX_CURVE_KEYS = 64
_MAPS1 = (("horizontal_inner", "rangeMapHorizontalInner"), ("horizontal_outer", "rangeMapHorizontalOuter"),
          ("vertical_down", "rangeMapVerticalDown"), ("vertical_up", "rangeMapVerticalUp"))
_MAPS0 = (("horizontal_inner", "lookAtHorizontalInner"), ("horizontal_outer", "lookAtHorizontalOuter"),
          ("vertical_down", "lookAtVerticalDown"), ("vertical_up", "lookAtVerticalUp"))


def read_look_at(state: ReadState) -> None:
    """``state.look_at``: the avatar's look-at ({} when it has none)."""
    if state.vrm1 is not None and isinstance(state.vrm1.get("lookAt"), dict):
        w, raw = "extensions.VRMC_vrm.lookAt", state.vrm1["lookAt"]
        kind = raw.get("type", "bone")
        if kind not in ("bone", "expression"):
            state.f.fail(f"{w}.type", f"expected 'bone' or 'expression', found {kind!r}")
        maps = {ours: _map(state, raw.get(theirs, {}), f"{w}.{theirs}", "inputMaxValue", "outputScale", kind)
                for ours, theirs in _MAPS1}
    elif state.vrm0 is not None and isinstance(state.vrm0.get("firstPerson"), dict):
        w, raw = "extensions.VRM.firstPerson", state.vrm0["firstPerson"]
        name = raw.get("lookAtTypeName", "Bone")
        if name not in ("Bone", "BlendShape"):
            state.f.fail(f"{w}.lookAtTypeName", f"expected 'Bone' or 'BlendShape', found {name!r}")
        kind = "bone" if name == "Bone" else "expression"
        maps = {ours: _map(state, raw.get(theirs, {}), f"{w}.{theirs}", "xRange", "yRange", kind)
                for ours, theirs in _MAPS0}
    else:
        return
    state.look_at = {"type": kind, **maps, "left_eye": int(state.bones.get("leftEye", -1)),
                     "right_eye": int(state.bones.get("rightEye", -1))}


def _map(state: ReadState, raw: Any, where: str, input_key: str, output_key: str, kind: str) -> dict:
    if not isinstance(raw, dict):
        state.f.fail(where, f"expected an object, found {type(raw).__name__}")
    out = {}
    for key, ours, default in ((input_key, "input_max", 90.0),
                               (output_key, "output_scale", 10.0 if kind == "bone" else 1.0)):
        value = raw.get(key, default)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value):
            state.f.fail(f"{where}.{key}", f"expected a finite number, found {value!r}")
        if key == input_key and value <= 0:
            state.f.fail(f"{where}.{key}", f"{value!r}: the input range must be > 0 degrees")
        out[ours] = float(value)
    curve = raw.get("curve")
    out["curve"] = [] if curve is None else _curve(state, curve, f"{where}.curve")
    return out


def _curve(state: ReadState, curve: Any, where: str) -> list[list[float]]:
    """A Unity AnimationCurve's keys, (time, value, in tangent, out tangent) each, times increasing."""
    if not isinstance(curve, list) or len(curve) % 4 or len(curve) > 4 * MAX_CURVE_KEYS:
        state.f.fail(where, f"expected an array of 4 numbers per key, at most {MAX_CURVE_KEYS} keys")
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in curve):
        state.f.fail(where, "expected finite numbers")
    keys = [[float(x) for x in curve[i:i + 4]] for i in range(0, len(curve), 4)]
    if any(b[0] <= a[0] for a, b in zip(keys, keys[1:])):
        state.f.fail(where, "the keys' times must increase")
    return keys
