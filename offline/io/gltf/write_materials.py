"""The written materials and textures, as core glTF 2.0 says them.

baseColorFactor/-Texture, emissive, alphaMode/alphaCutoff, doubleSided;
metallicFactor 0 and a roughness from the stored shininess (Blinn-Phong n ->
GGX: roughness = (2 / (n + 2))^(1/4)), since a character keeps no
metal/roughness, unless the file it came from had the material: then its
own metallic and roughness factors and its metal/roughness, normal,
occlusion and emissive textures (:mod:`.kept_parts`). An OBJ rig's ``hidden`` material is written BLEND with alpha
0 (kept, not drawn); its thin layers (eye occlusion, films, lashes) BLEND and
double-sided, with the fade the renderer gives them
(``render.layers.vertex_opacity``) as COLOR_0 alpha (RGBA, :mod:`.write_meshes`),
so any glTF viewer draws them see-through. A material kind other than skin
(eye, teeth, lashes …) and its specular/shininess go in
``material.extras.facepuppet`` for the importer (with, in a GLB or .gltf, a toon
material's MToon: :func:`.vrm_materials.write_mtoon`). Textures: PNG, lossless,
re-encoded from the stored texels; samplers from the stored codes. The
extensions (unlit, texture transform, MToon) are written after, each by its
own writer.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS
from facepuppet.runtime.model.character_parts import ALPHA_MODES
from facepuppet.runtime.render.layers import LAYER_KINDS

from facepuppet.offline.io.gltf.kept_parts import kept_material, kept_texture_info, write_kept_textures
from facepuppet.offline.io.gltf.write_state import WriteState

_ALPHA_NAME = {v: k for k, v in ALPHA_MODES.items()}
_KIND_NAME = {v: k for k, v in MATERIAL_KINDS.items()}


def write_materials(w: WriteState) -> tuple[list[dict], dict]:
    """The core glTF materials (``w.materials``) and the images, textures and samplers they use (see the module
    doc); the extension writers add to them after."""
    c, lk = w.c, w.c.look
    mats = []
    textures = _textures(w)  # first: a kept material names the written textures
    for i, name in enumerate(c.material_names):
        shine = float(c.material_params[i, 1])
        rough = float(np.clip((2.0 / (max(shine, 0.0) + 2.0)) ** 0.25, 0.0, 1.0))
        pbr: dict[str, Any] = {"metallicFactor": 0.0, "roughnessFactor": round(rough, 6)}
        mat: dict[str, Any] = {"name": name, "pbrMetallicRoughness": pbr}
        raw = kept_material(w, i)
        if raw:  # the file's own metal/roughness and other textures, as it had them
            _kept_core(w, raw, mat)
        kind = int(round(float(c.material_params[i, 2])))
        if kind != MATERIAL_KINDS["skin"]:  # read back by the importer; other readers ignore extras
            mat["extras"] = {"facepuppet": {"kind": _KIND_NAME.get(kind, "skin"),
                                            "specular": float(c.material_params[i, 0]),
                                            "shininess": float(c.material_params[i, 1])}}
        if lk is None:
            if kind == MATERIAL_KINDS["hidden"]:
                pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 0.0]
                mat["alphaMode"] = "BLEND"
            elif kind in LAYER_KINDS:  # thin see-through layers: COLOR_0 alpha holds their fade
                mat["alphaMode"] = "BLEND"
                mat["doubleSided"] = True
            mats.append(mat)
            continue
        base = [float(x) for x in lk.base_color[i]]
        if base != [1.0, 1.0, 1.0, 1.0]:
            pbr["baseColorFactor"] = base
        if int(lk.texture[i]) >= 0:
            pbr["baseColorTexture"] = {"index": int(lk.texture[i])}
        if np.any(lk.emissive[i] != 0):
            mat["emissiveFactor"] = [float(x) for x in lk.emissive[i]]
        mode = _ALPHA_NAME[int(lk.alpha[i, 0])]
        if mode != "OPAQUE":
            mat["alphaMode"] = mode
        if mode == "MASK":
            mat["alphaCutoff"] = float(lk.alpha[i, 1])
        if lk.shading[i, 1] > 0.5:
            mat["doubleSided"] = True
        mats.append(mat)
    w.materials = mats
    return mats, textures


def _kept_core(w: WriteState, raw: dict, mat: dict) -> None:
    """The core fields the look does not hold, from the file's material ``raw``: metallic and roughness factors
    (the spec's defaults, 1, where the file had none), the metal/roughness, normal, occlusion and emissive
    textures onto the written textures."""
    pbr = mat["pbrMetallicRoughness"]
    raw_pbr = raw.get("pbrMetallicRoughness") if isinstance(raw.get("pbrMetallicRoughness"), dict) else {}
    for key in ("metallicFactor", "roughnessFactor"):
        v = raw_pbr.get(key, 1.0)
        pbr[key] = float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else 1.0
    info = kept_texture_info(w, raw_pbr.get("metallicRoughnessTexture"))
    if info is not None:
        pbr["metallicRoughnessTexture"] = info
    for key in ("normalTexture", "occlusionTexture", "emissiveTexture"):
        info = kept_texture_info(w, raw.get(key))
        if info is not None:
            mat[key] = info


def _textures(w: WriteState) -> dict:
    """The look's textures (PNG from the stored texels; texture i is image i), then those kept raw from the file
    (:func:`.kept_parts.write_kept_textures`)."""
    lk = w.c.look
    images, textures, samplers = [], [], []
    sampler_of: dict[tuple, int] = {}
    names = lk.texture_names if lk is not None else ()
    if names:
        from PIL import Image
    for t, name in enumerate(names):
        png = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(lk.image(t)), "RGBA").save(png, format="PNG", compress_level=4)
        images.append({"name": name, "mimeType": "image/png", "bufferView": w.buf.view(png.getvalue())})
        codes = tuple(int(x) for x in lk.texture_info[t, 3:7])
        if codes not in sampler_of:
            sampler_of[codes] = len(samplers)
            samplers.append({k: v for k, v in zip(("magFilter", "minFilter", "wrapS", "wrapT"), codes) if v})
        textures.append({"name": name, "source": t, "sampler": sampler_of[codes]})
    write_kept_textures(w, images, textures, samplers, sampler_of)
    w.summary.n_textures = len(textures)
    w.textures = textures
    if not images:
        return {}
    return {"images": images, "textures": textures, "samplers": samplers}
