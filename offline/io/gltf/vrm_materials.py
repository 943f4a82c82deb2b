"""VRM's own materials: 0.x ``materialProperties`` (MToon and the unlit shaders) and 1.0 ``VRMC_materials_mtoon``.

A character keeps MToon in VRM 1.0's terms (shade colour, shading shift and
toony factors in the ``shading`` row of its look), so that one shader draws
both versions. VRM 0.x gives the lit range [_ShadeShift, lerp(1, _ShadeShift,
_ShadeToony)], converted both ways here; its colours are sRGB in the file and
linear in the character. A 0.x material property names its glTF material (else
its index does); VRM_USE_GLTFSHADER leaves the glTF material as it is. On a
material with both, ``VRMC_materials_mtoon`` wins.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS
from facepuppet.runtime.model.character_parts import SHADING

from facepuppet.offline.io.gltf.kept_parts import kept_texture_info
from facepuppet.offline.io.gltf.mtoon_convert import (
    merge_properties0,
    mtoon1_from_0,
    mtoon1_kept,
    properties0,
    properties0_from_1,
)
from facepuppet.offline.io.gltf.read_state import ReadState, extensions_of
from facepuppet.offline.io.gltf.write_state import WriteState

_KIND_NAME = {v: k for k, v in MATERIAL_KINDS.items()}


def read_material_properties(state: ReadState) -> None:
    """The shading rows of a VRM 0.x's MToon and unlit materials (``extensions.VRM.materialProperties``)."""
    if state.vrm0 is None:
        return
    f = state.f
    mats = f.items("materials")
    for i, row in _material_properties(state, mats).items():
        if row is not None:
            state.look.shading[i, :] = row
            state.look.shading[i, 1] = 1.0 if f.get(mats[i], "doubleSided", bool, f"materials[{i}]", False) else 0.0


def read_mtoon(state: ReadState) -> None:
    """The shading rows of the materials with ``VRMC_materials_mtoon`` (VRM 1.0), or with the same object in
    ``extras.facepuppet.mtoon`` (a GLB or .gltf that ``export-character`` wrote)."""
    f = state.f
    shading = state.look.shading
    for i, m in enumerate(f.items("materials")):
        mt1 = extensions_of(m).get("VRMC_materials_mtoon")
        mw = f"materials[{i}].extensions.VRMC_materials_mtoon"
        if not isinstance(mt1, dict):  # a GLB of ours keeps it beside its unlit fallback
            mt1, mw = facepuppet_mtoon(m), f"materials[{i}].extras.facepuppet.mtoon"
        if isinstance(mt1, dict):
            shading[i, 0] = SHADING["toon"]
            shading[i, 2:5] = f.numbers(mt1, "shadeColorFactor", 3, mw, [0, 0, 0])
            shading[i, 5] = f.get(mt1, "shadingShiftFactor", float, mw, 0.0)
            shading[i, 6] = f.get(mt1, "shadingToonyFactor", float, mw, 0.9)


def _material_properties(state: ReadState, mats: list) -> dict:
    """VRM 0.x ``materialProperties`` (matched to glTF materials by name) -> shading rows.

    MToon 0.x: ``_ShadeColor`` (sRGB in the file, decoded to linear here), and the 0.x
    shading range [_ShadeShift, lerp(1, _ShadeShift, _ShadeToony)] re-expressed in VRM
    1.0's terms (``shadingToonyFactor`` = (2 − range width) / 2, ``shadingShiftFactor`` =
    −range centre), so that one shader draws both. Unlit VRM shaders -> unlit.
    """
    f = state.f
    props = state.vrm0.get("materialProperties", [])
    if not isinstance(props, list):
        f.fail("extensions.VRM.materialProperties", "expected an array")
    # matched by name; a name that is an array or an object (not a JSON key of any use) matches nothing
    by_name = {m.get("name"): i for i, m in enumerate(mats) if isinstance(m, dict)
               and not isinstance(m.get("name"), (list, dict))}
    out: dict[int, np.ndarray | None] = {}
    for k, prop in enumerate(props):
        w = f"extensions.VRM.materialProperties[{k}]"
        if not isinstance(prop, dict):
            f.fail(w, "expected an object")
        name = prop.get("name")
        i = k if k < len(mats) else None
        if not isinstance(name, (list, dict)):
            i = by_name.get(name, i)
        if i is None:
            continue
        shader = prop.get("shader", "")
        row = np.zeros(8)
        if shader == "VRM/MToon":
            floats = f.get(prop, "floatProperties", dict, w, {})
            vectors = f.get(prop, "vectorProperties", dict, w, {})
            shade = f.numbers(vectors, "_ShadeColor", 4, f"{w}.vectorProperties", [0.97, 0.81, 0.86, 1])
            shift = f.get(floats, "_ShadeShift", float, f"{w}.floatProperties", 0.0)
            toony = f.get(floats, "_ShadeToony", float, f"{w}.floatProperties", 0.9)
            lo, hi = shift, 1.0 + (shift - 1.0) * toony
            row[0] = SHADING["toon"]
            row[2:5] = _srgb_to_linear(np.clip(shade[:3], 0, 1))
            row[5] = -(lo + hi) / 2
            row[6] = np.clip((2.0 - (hi - lo)) / 2, 0.0, 1.0)
            out[i] = row
        elif isinstance(shader, str) and shader.startswith("VRM/Unlit"):
            row[0] = SHADING["unlit"]
            out[i] = row
        else:
            out[i] = None  # VRM_USE_GLTFSHADER: the glTF material as it is
    return out


def write_material_properties(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``materialProperties``: one per written material, in order."""
    vrm["materialProperties"] = [_material0(w, i, m) for i, m in enumerate(w.materials)]


def write_mtoon(w: WriteState, materials: list[dict]) -> None:
    """``VRMC_materials_mtoon`` on each toon material of a VRM 1.0: the shade from the look (its texture: the
    file's, else the base colour's), the rest (outline, rim, matcap, UV animation) from the file's own MToon,
    converted from a VRM 0.x's material property (:mod:`.mtoon_convert`). A GLB or .gltf keeps the same object
    in ``extras.facepuppet.mtoon`` (for the importer; its viewers draw the unlit fallback), not as the extension:
    beside KHR_materials_unlit it would be two shading extensions on one material."""
    lk = w.c.look
    if w.fmt == "vrm0" or lk is None:
        return
    props = properties0(w)
    for i, mat in enumerate(materials):
        if int(lk.shading[i, 0]) != SHADING["toon"]:
            continue
        mt: dict[str, Any] = {"specVersion": "1.0"}
        prop = props.get(i)
        if prop is not None and prop.get("shader") == "VRM/MToon":
            mt.update(mtoon1_from_0(w, prop))
            _core_textures_from_0(w, prop, mat)
        else:
            mt.update(mtoon1_kept(w, i))
        mt.update({"specVersion": "1.0", "shadeColorFactor": [float(x) for x in lk.shading[i, 2:5]],
                   "shadingShiftFactor": float(lk.shading[i, 5]), "shadingToonyFactor": float(lk.shading[i, 6])})
        if int(lk.texture[i]) >= 0 and "shadeMultiplyTexture" not in mt:
            mt["shadeMultiplyTexture"] = {"index": int(lk.texture[i])}
        if w.fmt != "vrm1":
            kind, spec, shine = (float(x) for x in w.c.material_params[i, [2, 0, 1]])
            ours = mat.setdefault("extras", {}).setdefault("facepuppet", {
                "kind": _KIND_NAME.get(int(round(kind)), "skin"), "specular": spec, "shininess": shine})
            ours["mtoon"] = mt
            continue
        mat.setdefault("extensions", {})["VRMC_materials_mtoon"] = mt
        w.ext_used.add("VRMC_materials_mtoon")


def facepuppet_mtoon(m: Any) -> dict | None:
    """A material's ``extras.facepuppet.mtoon`` (MToon as VRMC_materials_mtoon says it), or None."""
    extras = m.get("extras") if isinstance(m, dict) else None
    ours = extras.get("facepuppet") if isinstance(extras, dict) else None
    mt = ours.get("mtoon") if isinstance(ours, dict) else None
    return mt if isinstance(mt, dict) else None


def _core_textures_from_0(w: WriteState, prop: dict, mat: dict) -> None:
    """A VRM 0.x MToon's normal map (``_BumpMap``, ``_BumpScale``) and emission map onto the core material,
    where it has none of its own."""
    tex = prop.get("textureProperties") if isinstance(prop.get("textureProperties"), dict) else {}
    fl = prop.get("floatProperties") if isinstance(prop.get("floatProperties"), dict) else {}
    for key0, key in (("_BumpMap", "normalTexture"), ("_EmissionMap", "emissiveTexture")):
        info = kept_texture_info(w, {"index": tex.get(key0)})
        if info is not None and key not in mat:
            mat[key] = info
            if key0 == "_BumpMap" and isinstance(fl.get("_BumpScale"), (int, float)):
                info["scale"] = float(fl["_BumpScale"])


def _material0(w: WriteState, i: int, mat: dict) -> dict:
    """The VRM 0.x material property of material ``i``: VRM/MToon, a VRM/Unlit shader, or the glTF material
    as it is (VRM_USE_GLTFSHADER); over the file's own property when it came from a VRM 0.x (what the look
    does not say stays), or with a VRM 1.0's outline, rim and the rest converted."""
    prop = _look_material0(w, i, mat)
    raw = properties0(w).get(i)
    if raw is not None:
        return merge_properties0(w, raw, prop)
    if prop["shader"] == "VRM/MToon":
        mt = mtoon1_kept(w, i)
        if mt:
            fl, vec, tex, kw = properties0_from_1(w, mt, mat)
            prop["floatProperties"] = {**fl, **prop["floatProperties"]}
            prop["vectorProperties"] = {**vec, **prop["vectorProperties"]}
            prop["textureProperties"] = {**tex, **prop["textureProperties"]}
            prop["keywordMap"] = {**kw, **prop["keywordMap"]}
    return prop


def _look_material0(w: WriteState, i: int, mat: dict) -> dict:
    """The VRM 0.x material property of material ``i`` from its look alone."""
    lk = w.c.look
    prop = {"name": mat["name"], "shader": "VRM_USE_GLTFSHADER", "renderQueue": -1, "floatProperties": {},
            "vectorProperties": {}, "textureProperties": {}, "keywordMap": {}, "tagMap": {}}
    if lk is None:
        return prop
    mode = int(lk.alpha[i, 0])
    shading = int(lk.shading[i, 0])
    tag = ("Opaque", "TransparentCutout", "Transparent")[mode]
    queue = (2000, 2450, 3000)[mode]
    tex = int(lk.texture[i])
    ou, ov, _, su, sv = (float(x) for x in lk.uv_transform[i])
    main_st = [ou, 1.0 - sv - ov, su, sv]  # Unity's texture ST: v from the bottom
    if shading == SHADING["unlit"]:
        shader = ("VRM/UnlitTexture", "VRM/UnlitCutout", "VRM/UnlitTransparent")[mode]
        prop.update(shader=shader, renderQueue=queue, tagMap={"RenderType": tag},
                    vectorProperties={"_Color": [*_srgb_encode(lk.base_color[i, :3]).tolist(),
                                                 float(lk.base_color[i, 3])], "_MainTex": main_st},
                    floatProperties={"_Cutoff": float(lk.alpha[i, 1])},
                    textureProperties={"_MainTex": tex} if tex >= 0 else {})
        return prop
    if shading != SHADING["toon"]:
        return prop
    # the character keeps VRM 1.0's terms: shift = -(range centre), toony = (2 - width) / 2
    centre, width = -float(lk.shading[i, 5]), 2.0 - 2.0 * float(lk.shading[i, 6])
    lo, hi = centre - width / 2, centre + width / 2
    toony = float(np.clip((hi - 1.0) / (lo - 1.0), 0.0, 1.0)) if abs(lo - 1.0) > 1e-9 else 1.0
    double = lk.shading[i, 1] > 0.5
    blend = {0: (1, 0, 1), 1: (1, 0, 1), 2: (5, 10, 0)}[mode]  # _SrcBlend, _DstBlend, _ZWrite
    prop.update(
        shader="VRM/MToon", renderQueue=queue, tagMap={"RenderType": tag},
        keywordMap={k: True for k, on in (("_ALPHATEST_ON", mode == 1), ("_ALPHABLEND_ON", mode == 2)) if on},
        floatProperties={"_Cutoff": float(lk.alpha[i, 1]), "_ShadeShift": lo, "_ShadeToony": toony,
                         "_BlendMode": float(mode), "_CullMode": 0.0 if double else 2.0,
                         "_SrcBlend": float(blend[0]), "_DstBlend": float(blend[1]), "_ZWrite": float(blend[2])},
        vectorProperties={"_Color": [*_srgb_encode(lk.base_color[i, :3]).tolist(), float(lk.base_color[i, 3])],
                          "_ShadeColor": [*_srgb_encode(lk.shading[i, 2:5]).tolist(), 1.0],
                          "_EmissionColor": [*_srgb_encode(lk.emissive[i]).tolist(), 1.0], "_MainTex": main_st},
        textureProperties={"_MainTex": tex, "_ShadeTexture": tex} if tex >= 0 else {})
    return prop


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _srgb_encode(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
