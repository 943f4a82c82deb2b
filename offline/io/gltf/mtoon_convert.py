"""MToon's parameters the look does not hold (outline, rim, matcap, GI, UV animation), between VRM 0.x and 1.0.

The look keeps MToon's shade colour, shift and toony factors (the writers in
:mod:`.vrm_materials` write them); the rest is kept raw from the file
(VRM 0.x ``materialProperties`` inside the kept VRM extension, VRM 1.0
``VRMC_materials_mtoon`` in ``settings.source.kept.materials``, or its copy in
``extras.facepuppet.mtoon`` of a GLB that export-character wrote) and written
back here, in the file's version or converted field by field as the VRM
migration does it (and three-vrm's 0.x compatibility reads it): 0.x colours
are sRGB, 1.0's linear; ``_OutlineWidth`` is in centimetres, ``outlineWidthFactor``
in metres; ``outlineLightingMixFactor`` is ``_OutlineLightingMix`` in the 0.x
colour mode "mixed" (1), else 0; ``giEqualizationFactor`` = 1 − ``_IndirectLightIntensity``;
the V scroll speed changes sign (Unity's V runs up). Texture indices are the
file's, put onto the written textures (``w.file_texture``).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.kept_parts import MTOON_TEXTURES, kept_material, kept_texture_info
from facepuppet.offline.io.gltf.write_state import WriteState

_WIDTH_MODES = ("none", "worldCoordinates", "screenCoordinates")
#: 0.x texture property -> VRMC_materials_mtoon texture field (the base colour and shade textures are the look's)
_TEXTURES_0_TO_1 = {"_SphereAdd": "matcapTexture", "_RimTexture": "rimMultiplyTexture",
                    "_OutlineWidthTexture": "outlineWidthMultiplyTexture",
                    "_UvAnimMaskTexture": "uvAnimationMaskTexture"}


def properties0(w: WriteState) -> dict[int, dict]:
    """The kept VRM 0.x material property of each stored material (a VRM 0.x source only), matched as the
    reader matches them: by material name, else by index."""
    src = w.c.source
    raw = src.get("vrm_extension")
    props = raw.get("materialProperties") if src.get("format") == "vrm0" and isinstance(raw, dict) else None
    if not isinstance(props, list):
        return {}
    names = {n: i for i, n in enumerate(w.c.material_names)}
    out = {}
    for k, p in enumerate(props):
        if isinstance(p, dict):
            i = names.get(p.get("name"), k) if isinstance(p.get("name"), str) else k
            if i < len(w.c.material_names):
                out.setdefault(i, p)
    return out


def mtoon1_kept(w: WriteState, i: int) -> dict:
    """The file's own VRMC_materials_mtoon of stored material ``i`` (a VRM 1.0 or glTF source), its textures
    onto the written ones; {} when it had none."""
    raw = kept_material(w, i)
    ext = raw.get("extensions")
    mt = ext.get("VRMC_materials_mtoon") if isinstance(ext, dict) else None
    if not isinstance(mt, dict):  # a GLB of ours: the same object in extras (see vrm_materials.write_mtoon)
        extras = raw.get("extras") if isinstance(raw.get("extras"), dict) else {}
        ours = extras.get("facepuppet") if isinstance(extras.get("facepuppet"), dict) else {}
        mt = ours.get("mtoon")
    if not isinstance(mt, dict):
        return {}
    out = copy.deepcopy(mt)
    for key in MTOON_TEXTURES:
        if key in out:
            info = kept_texture_info(w, out[key])
            if info is None:
                del out[key]
            else:
                out[key] = info
    return out


def mtoon1_from_0(w: WriteState, prop: dict) -> dict:
    """The VRMC_materials_mtoon fields of a VRM 0.x ``VRM/MToon`` material property, beyond the shade."""
    fl = _dict(prop, "floatProperties")
    vec = _dict(prop, "vectorProperties")
    tex = _dict(prop, "textureProperties")
    out: dict[str, Any] = {}
    out["giEqualizationFactor"] = float(np.clip(1.0 - _num(fl, "_IndirectLightIntensity", 0.1), 0, 1))
    out["rimLightingMixFactor"] = _num(fl, "_RimLightingMix", 0.0)
    out["parametricRimColorFactor"] = _linear(vec.get("_RimColor"), [0, 0, 0])
    out["parametricRimFresnelPowerFactor"] = _num(fl, "_RimFresnelPower", 1.0)
    out["parametricRimLiftFactor"] = _num(fl, "_RimLift", 0.0)
    mode = int(_num(fl, "_OutlineWidthMode", 0.0))
    out["outlineWidthMode"] = _WIDTH_MODES[mode] if 0 <= mode < 3 else "none"
    out["outlineWidthFactor"] = 0.01 * _num(fl, "_OutlineWidth", 0.0)
    out["outlineColorFactor"] = _linear(vec.get("_OutlineColor"), [0, 0, 0])
    mixed = int(_num(fl, "_OutlineColorMode", 0.0)) == 1
    out["outlineLightingMixFactor"] = _num(fl, "_OutlineLightingMix", 1.0) if mixed else 0.0
    out["uvAnimationScrollXSpeedFactor"] = _num(fl, "_UvAnimScrollX", 0.0)
    out["uvAnimationScrollYSpeedFactor"] = -_num(fl, "_UvAnimScrollY", 0.0)
    out["uvAnimationRotationSpeedFactor"] = _num(fl, "_UvAnimRotation", 0.0)
    keywords = _dict(prop, "keywordMap")
    out["transparentWithZWrite"] = bool(keywords.get("_ALPHABLEND_ON")) and _num(fl, "_ZWrite", 0.0) == 1.0
    for key0, key1 in _TEXTURES_0_TO_1.items():
        info = kept_texture_info(w, {"index": tex.get(key0)})
        if info is not None:
            out[key1] = info
            if key1 == "matcapTexture":
                out["matcapFactor"] = [1.0, 1.0, 1.0]
    return out


def properties0_from_1(w: WriteState, mt: dict, core: dict) -> tuple[dict, dict, dict, dict]:
    """(floatProperties, vectorProperties, textureProperties, keywordMap) of a VRM 0.x MToon from a
    VRMC_materials_mtoon ``mt`` whose textures are already the written ones (and the written core material
    ``core``, for its normal and emissive textures)."""
    fl: dict[str, float] = {}
    vec: dict[str, list] = {}
    tex: dict[str, int] = {}
    kw: dict[str, bool] = {}
    fl["_IndirectLightIntensity"] = float(np.clip(1.0 - _num(mt, "giEqualizationFactor", 0.9), 0, 1))
    fl["_RimLightingMix"] = _num(mt, "rimLightingMixFactor", 1.0)
    vec["_RimColor"] = [*_srgb(mt.get("parametricRimColorFactor"), [0, 0, 0]), 1.0]
    fl["_RimFresnelPower"] = _num(mt, "parametricRimFresnelPowerFactor", 5.0)
    fl["_RimLift"] = _num(mt, "parametricRimLiftFactor", 0.0)
    mode = mt.get("outlineWidthMode", "none")
    fl["_OutlineWidthMode"] = float(_WIDTH_MODES.index(mode)) if mode in _WIDTH_MODES else 0.0
    fl["_OutlineWidth"] = 100.0 * _num(mt, "outlineWidthFactor", 0.0)
    vec["_OutlineColor"] = [*_srgb(mt.get("outlineColorFactor"), [0, 0, 0]), 1.0]
    mix = _num(mt, "outlineLightingMixFactor", 1.0)
    fl["_OutlineColorMode"] = 1.0 if mix > 0 else 0.0
    fl["_OutlineLightingMix"] = mix
    fl["_UvAnimScrollX"] = _num(mt, "uvAnimationScrollXSpeedFactor", 0.0)
    fl["_UvAnimScrollY"] = -_num(mt, "uvAnimationScrollYSpeedFactor", 0.0)
    fl["_UvAnimRotation"] = _num(mt, "uvAnimationRotationSpeedFactor", 0.0)
    for key0, key1 in _TEXTURES_0_TO_1.items():
        if isinstance(mt.get(key1), dict) and isinstance(mt[key1].get("index"), int):
            tex[key0] = mt[key1]["index"]
    if isinstance(core.get("normalTexture"), dict):
        tex["_BumpMap"] = core["normalTexture"]["index"]
        fl["_BumpScale"] = _num(core["normalTexture"], "scale", 1.0)
    if isinstance(core.get("emissiveTexture"), dict):
        tex["_EmissionMap"] = core["emissiveTexture"]["index"]
    if mode in ("worldCoordinates", "screenCoordinates"):
        kw["MTOON_OUTLINE_WIDTH_WORLD" if mode == "worldCoordinates" else "MTOON_OUTLINE_WIDTH_SCREEN"] = True
        kw["MTOON_OUTLINE_COLOR_MIXED" if mix > 0 else "MTOON_OUTLINE_COLOR_FIXED"] = True
    return fl, vec, tex, kw


def merge_properties0(w: WriteState, raw: dict, prop: dict) -> dict:
    """A VRM 0.x material property ``prop`` (written from the look) over the file's own ``raw`` one: every raw
    float, vector, keyword and tag the look does not say stays, raw texture indices onto the written ones."""
    out = copy.deepcopy(raw)
    for key in ("floatProperties", "vectorProperties", "keywordMap", "tagMap"):
        out[key] = {**_dict(raw, key), **prop.get(key, {})}
    textures = {}
    for k, t in _dict(raw, "textureProperties").items():
        info = kept_texture_info(w, {"index": t})
        if info is not None:
            textures[k] = info["index"]
    out["textureProperties"] = {**textures, **prop.get("textureProperties", {})}
    if raw.get("shader") == "VRM_USE_GLTFSHADER" and prop["shader"] != "VRM/MToon":
        out["name"] = prop["name"]  # the glTF material says it all (an unlit one by KHR_materials_unlit)
        return out
    for key in ("name", "shader", "renderQueue"):
        out[key] = prop[key]
    return out


def _dict(o: dict, key: str) -> dict:
    v = o.get(key) if isinstance(o, dict) else None
    return v if isinstance(v, dict) else {}


def _num(o: dict, key: str, default: float) -> float:
    v = o.get(key) if isinstance(o, dict) else None
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) else default


def _colour(v: Any, default: list) -> np.ndarray:
    ok = isinstance(v, list) and len(v) >= 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                     for x in v[:3])
    return np.clip(np.asarray(v[:3] if ok else default, dtype=np.float64), 0.0, 1.0)


def _linear(v: Any, default: list) -> list[float]:
    c = _colour(v, default)
    return [float(x) for x in np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)]


def _srgb(v: Any, default: list) -> list[float]:
    c = _colour(v, default)
    return [float(x) for x in np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)]
