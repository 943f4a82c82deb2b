"""The Khronos material extensions a character's look keeps: unlit, emissive strength, texture transform.

* ``KHR_materials_unlit``: the material is drawn without lighting (shading
  ``unlit``); read and written.
* ``KHR_materials_emissive_strength``: multiplies the emissive factor; read
  (the character keeps the product, written back as the emissive factor).
* ``KHR_texture_transform`` on the base colour texture: offset, rotation,
  scale of its texture coordinates; read and written (when not the identity).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character_parts import SHADING

from facepuppet.offline.io.gltf.kept_parts import kept_material
from facepuppet.offline.io.gltf.read_state import ReadState, extensions_of
from facepuppet.offline.io.gltf.write_state import WriteState


def read_emissive_strength(state: ReadState) -> None:
    f = state.f
    for i, m in enumerate(f.items("materials")):
        strength = extensions_of(m).get("KHR_materials_emissive_strength")
        if isinstance(strength, dict):
            state.look.emissive[i] *= f.get(strength, "emissiveStrength", float, f"materials[{i}].extensions."
                                            "KHR_materials_emissive_strength", 1.0)


def read_unlit(state: ReadState) -> None:
    for i, m in enumerate(state.f.items("materials")):
        if "KHR_materials_unlit" in extensions_of(m):
            state.look.shading[i, 0] = SHADING["unlit"]


def read_texture_transform(state: ReadState) -> None:
    f = state.f
    for i, m in enumerate(f.items("materials")):
        info = m.get("pbrMetallicRoughness", {}).get("baseColorTexture")  # both checked by the core reader
        tt = extensions_of(info).get("KHR_texture_transform")
        if isinstance(tt, dict):
            ttw = f"materials[{i}].pbrMetallicRoughness.baseColorTexture.extensions.KHR_texture_transform"
            off = f.numbers(tt, "offset", 2, ttw, [0, 0])
            rot = f.get(tt, "rotation", float, ttw, 0.0)
            scale = f.numbers(tt, "scale", 2, ttw, [1, 1])
            state.look.uv_transform[i] = (off[0], off[1], rot, scale[0], scale[1])


def write_texture_transform(w: WriteState, materials: list[dict]) -> None:
    lk = w.c.look
    if lk is None:
        return
    for i, mat in enumerate(materials):
        info = mat["pbrMetallicRoughness"].get("baseColorTexture")
        uvt = [float(x) for x in lk.uv_transform[i]]
        if info is not None and not np.allclose(uvt, (0, 0, 0, 1, 1), atol=0):
            info["extensions"] = {"KHR_texture_transform": {"offset": uvt[:2], "rotation": uvt[2],
                                                            "scale": uvt[3:]}}
            w.ext_used.add("KHR_texture_transform")


def write_unlit(w: WriteState, materials: list[dict]) -> None:
    """KHR_materials_unlit on the unlit materials, and on the toon ones as the plain-glTF fallback (a viewer
    without MToon draws them unlit, as an avatar app's flat-lit toon, not as dark lit PBR): in a GLB, a .gltf
    and a VRM 0.x (whose MToon is in the VRM extension). In a VRM 1.0 a toon material carries
    VRMC_materials_mtoon, and the unlit fallback beside it only where the file had both (the validator warns
    about two shading extensions on one material)."""
    lk = w.c.look
    if lk is None:
        return
    for i, mat in enumerate(materials):
        shading = int(lk.shading[i, 0])
        toon = shading == SHADING["toon"]
        had = {"KHR_materials_unlit", "VRMC_materials_mtoon"} <= set(extensions_of(kept_material(w, i)))
        if shading == SHADING["unlit"] or (toon and (w.fmt != "vrm1" or had)):
            mat.setdefault("extensions", {})["KHR_materials_unlit"] = {}
            w.ext_used.add("KHR_materials_unlit")
