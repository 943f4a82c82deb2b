"""Expressions' binds on materials: 0.x ``materialValues``, 1.0 ``materialColorBinds`` / ``textureTransformBinds``.

The character keeps them raw (in the kept VRM extension); the expression
writers put them back on the expression of the same name, in the version
being written, converted as VRM runtimes read them (three-vrm's 0.x loader):
a 0.x property ``_Color``, ``_EmissionColor``, ``_ShadeColor``, ``_RimColor``
or ``_OutlineColor`` is the 1.0 colour bind of type ``color``,
``emissionColor``, ``shadeColor``, ``rimColor``, ``outlineColor``, its
target value taken as it is (three-vrm, the reference this project draws
against, applies a 0.x bind's colour unconverted, unlike a 0.x material's
own ``_Color``, which it decodes from sRGB); ``_MainTex_ST`` (scale u, v,
offset u, v with v from the bottom) is a texture transform bind whose v
offset is 1 − v offset − v scale. 1.0's ``matcapColor`` has no 0.x property
and is dropped going to 0.x (with a warning). A 0.x bind names its material,
a 1.0 bind its index: the written materials are the character's, in order.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from facepuppet.runtime.mapping.vrm_names import VRM0_PRESETS, VRM1_FROM_VRM0

from facepuppet.offline.io.gltf.write_state import WriteState

_COLOUR_0_TO_1 = {"_Color": "color", "_EmissionColor": "emissionColor", "_ShadeColor": "shadeColor",
                  "_RimColor": "rimColor", "_OutlineColor": "outlineColor"}
_COLOUR_1_TO_0 = {v: k for k, v in _COLOUR_0_TO_1.items()}
_VRM0_BY_LOWER = {p.lower(): p for p in VRM0_PRESETS}
_VRM0_FROM_VRM1 = {v: k for k, v in VRM1_FROM_VRM0.items()}


@dataclass
class MaterialBinds:
    """One expression's material binds in VRM 1.0's terms: colours (material, type, linear RGBA) and texture
    transforms (material, scale, offset)."""

    colours: list[tuple[int, str, list[float]]] = field(default_factory=list)
    transforms: list[tuple[int, list[float], list[float]]] = field(default_factory=list)


def material_binds(w: WriteState) -> dict[str, MaterialBinds]:
    """The kept material binds of each expression, by the name the reader gave the expression."""
    src = w.c.source
    raw = src.get("vrm_extension")
    if not isinstance(raw, dict):
        return {}
    if src.get("format") == "vrm0":
        return _from0(w, raw)
    if src.get("format") == "vrm1":
        return _from1(w, raw)
    return {}


def _from0(w: WriteState, raw: dict) -> dict[str, MaterialBinds]:
    bsm = raw.get("blendShapeMaster") if isinstance(raw.get("blendShapeMaster"), dict) else {}
    groups = bsm.get("blendShapeGroups") if isinstance(bsm.get("blendShapeGroups"), list) else []
    material = {n: i for i, n in enumerate(w.c.material_names)}
    out = {}
    for g, group in enumerate(groups):
        if not isinstance(group, dict) or not isinstance(group.get("materialValues"), list):
            continue
        preset = _VRM0_BY_LOWER.get(str(group.get("presetName", "unknown")).lower(), "")
        name = preset or (group.get("name") if isinstance(group.get("name"), str) else "") or f"expression{g}"
        binds = MaterialBinds()
        for v in group["materialValues"]:
            if not (isinstance(v, dict) and v.get("materialName") in material and _numbers(v.get("targetValue"), 4)):
                continue
            m, prop, tv = material[v["materialName"]], v.get("propertyName"), [float(x) for x in v["targetValue"][:4]]
            if prop == "_MainTex_ST":
                binds.transforms.append((m, tv[0:2], [tv[2], 1.0 - tv[3] - tv[1]]))
            elif prop in _COLOUR_0_TO_1:
                binds.colours.append((m, _COLOUR_0_TO_1[prop], tv))
            else:
                w.warn(f"blendShapeGroups[{g}].materialValues: property {prop!r} has no VRM bind; dropped")
        if binds.colours or binds.transforms:
            out[name] = binds
    return out


def _from1(w: WriteState, raw: dict) -> dict[str, MaterialBinds]:
    ex = raw.get("expressions") if isinstance(raw.get("expressions"), dict) else {}
    n_materials = len(w.c.material_names)
    out = {}
    for group in ("preset", "custom"):
        table = ex.get(group) if isinstance(ex.get(group), dict) else {}
        for key, e in table.items():
            if not isinstance(e, dict):
                continue
            name = (_VRM0_FROM_VRM1.get(key, "") if group == "preset" else "") or key
            binds = MaterialBinds()
            for b in e.get("materialColorBinds", []) if isinstance(e.get("materialColorBinds"), list) else []:
                m = b.get("material") if isinstance(b, dict) else None
                if isinstance(m, int) and 0 <= m < n_materials and isinstance(b.get("type"), str) \
                        and _numbers(b.get("targetValue"), 3):
                    tv = [float(x) for x in b["targetValue"]]
                    binds.colours.append((m, b["type"], tv[:3] + [tv[3] if len(tv) > 3 else 1.0]))
            for b in e.get("textureTransformBinds", []) if isinstance(e.get("textureTransformBinds"), list) else []:
                m = b.get("material") if isinstance(b, dict) else None
                if isinstance(m, int) and 0 <= m < n_materials:
                    scale = [float(x) for x in b["scale"]] if _numbers(b.get("scale"), 2) else [1.0, 1.0]
                    offset = [float(x) for x in b["offset"]] if _numbers(b.get("offset"), 2) else [0.0, 0.0]
                    binds.transforms.append((m, scale[:2], offset[:2]))
            if binds.colours or binds.transforms:
                out[name] = binds
    return out


def write_binds0(w: WriteState, name: str, binds: MaterialBinds | None) -> list[dict]:
    """VRM 0.x ``materialValues`` of an expression."""
    if binds is None:
        return []
    out = []
    for m, kind, rgba in binds.colours:
        if kind not in _COLOUR_1_TO_0:
            w.warn(f"expression {name!r}: a {kind} bind has no VRM 0.x property; dropped")
            continue
        out.append({"materialName": w.c.material_names[m], "propertyName": _COLOUR_1_TO_0[kind],
                    "targetValue": [float(x) for x in rgba]})
    for m, scale, offset in binds.transforms:
        out.append({"materialName": w.c.material_names[m], "propertyName": "_MainTex_ST",
                    "targetValue": [scale[0], scale[1], offset[0], 1.0 - offset[1] - scale[1]]})
    return out


def write_binds1(binds: MaterialBinds | None) -> dict[str, list]:
    """VRM 1.0 ``materialColorBinds`` and ``textureTransformBinds`` of an expression (only those it has)."""
    if binds is None:
        return {}
    out: dict[str, list] = {}
    if binds.colours:
        out["materialColorBinds"] = [{"material": m, "type": kind, "targetValue": [float(x) for x in rgba]}
                                     for m, kind, rgba in binds.colours]
    if binds.transforms:
        out["textureTransformBinds"] = [{"material": m, "scale": list(scale), "offset": list(offset)}
                                        for m, scale, offset in binds.transforms]
    return out


def _numbers(v: Any, n: int) -> bool:
    return isinstance(v, list) and len(v) >= n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in v)
