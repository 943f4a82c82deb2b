"""Small VRM files built in code for MToon and material binds: one ball, one MToon (or plain glTF) material.

Written with the tests' own glTF writer (:mod:`helpers.gltf_writer`), independent of the reader under
test: a unit ball at the origin with an outline, and an expression ``Tint`` that binds the material's
colour (VRM 1.0 ``materialColorBinds``, VRM 0.x ``materialValues``).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from helpers.gltf_writer import GltfBuilder
from helpers.small_characters import uv_sphere


def ball_vrm(path: Path, *, version: str = "1.0", outline_mode: str = "screenCoordinates",
             outline_width: float = 0.01, tint: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0),
             base: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0),
             rim: tuple[float, float, float] = (0.0, 0.0, 0.0), half_width_texture: bool = False,
             mtoon_textures: dict | None = None, mtoon_extra: dict | None = None) -> Path:
    """A VRM (``version`` "1.0" or "0.x") of a unit ball with an MToon material (``base`` colour, linear; white
    shade; outline red, unlit by the lighting mix; parametric ``rim`` colour, fresnel power 2) and an
    expression ``Tint`` binding its colour to ``tint``. ``half_width_texture`` (1.0 only): an outline width
    texture whose green is 1 where u < 0.5 and 0 elsewhere (u runs round the ball: its +x half, seen from +z,
    against its -x half). ``mtoon_textures``: {VRMC_materials_mtoon texture field: (r, g, b) uint8}, each a
    uniform 2x2 PNG; ``mtoon_extra``: more VRMC_materials_mtoon fields (1.0)."""
    v, tris = uv_sphere()
    b = GltfBuilder()
    pos = b.accessor(v.astype(np.float32), minmax=True)
    nrm = b.accessor((v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32))
    idx = b.accessor(tris.astype(np.uint32).ravel())
    u = (v[:, 0] > 0).astype(np.float32) * 0.5 + 0.25  # 0.75 on the +x half, 0.25 on the -x half
    uv = b.accessor(np.stack([u, np.full(len(v), 0.5, np.float32)], axis=1))
    doc = b.doc
    doc["meshes"] = [{"name": "ball", "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm,
                                                                     "TEXCOORD_0": uv},
                                                      "indices": idx, "material": 0}]}]
    doc["nodes"] = [{"name": "ball", "mesh": 0}]
    doc["scenes"], doc["scene"] = [{"nodes": [0]}], 0
    material = {"name": "Ball", "pbrMetallicRoughness": {"baseColorFactor": list(base), "metallicFactor": 0.0}}
    if version == "1.0":
        material["extensions"] = {"VRMC_materials_mtoon": {
            "specVersion": "1.0", "shadeColorFactor": [1, 1, 1], "outlineWidthMode": outline_mode,
            "outlineWidthFactor": outline_width, "outlineColorFactor": [1, 0, 0], "outlineLightingMixFactor": 0.0,
            "parametricRimColorFactor": list(rim), "parametricRimFresnelPowerFactor": 2.0}}
        mt = material["extensions"]["VRMC_materials_mtoon"]
        mt.update(mtoon_extra or {})
        images = dict(mtoon_textures or {})
        if half_width_texture:
            pixels = np.zeros((4, 4, 3), np.uint8)
            pixels[:, :2, 1] = 255
            images["outlineWidthMultiplyTexture"] = pixels
        for field, pixels in images.items():
            pixels = np.broadcast_to(np.asarray(pixels, np.uint8), (2, 2, 3)) if np.ndim(pixels) == 1 else pixels
            png = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(pixels)).save(png, format="PNG")
            doc.setdefault("images", []).append({"bufferView": b.view(png.getvalue()), "mimeType": "image/png"})
            doc["samplers"] = [{"magFilter": 9728, "minFilter": 9728}]
            doc.setdefault("textures", []).append({"source": len(doc["images"]) - 1, "sampler": 0})
            mt[field] = {"index": len(doc["textures"]) - 1}
        doc["extensions"] = {"VRMC_vrm": {
            "specVersion": "1.0", "meta": {"name": "ball", "authors": ["tests"], "licenseUrl": "https://vrm.dev/licenses/1.0/"},
            "humanoid": {"humanBones": {}},
            "expressions": {"custom": {"Tint": {"materialColorBinds": [
                {"material": 0, "type": "color", "targetValue": list(tint)}]}}}}}
        doc["extensionsUsed"] = ["VRMC_vrm", "VRMC_materials_mtoon"]
    else:
        mode = {"none": 0, "worldCoordinates": 1, "screenCoordinates": 2}[outline_mode]
        srgb = [float(c) if c <= 0.0031308 else float(1.055 * c ** (1 / 2.4) - 0.055) for c in base[:3]]
        doc["extensions"] = {"VRM": {
            "exporterVersion": "tests", "meta": {"title": "ball", "author": "tests"},
            "humanoid": {"humanBones": []},
            "materialProperties": [{
                "name": "Ball", "shader": "VRM/MToon", "renderQueue": 2000,
                "floatProperties": {"_OutlineWidthMode": mode, "_OutlineWidth": 100.0 * outline_width,
                                    "_OutlineColorMode": 0, "_ShadeShift": 0, "_ShadeToony": 0.9},
                "vectorProperties": {"_Color": [*srgb, base[3]], "_ShadeColor": [1, 1, 1, 1],
                                     "_OutlineColor": [1, 0, 0, 1]},
                "textureProperties": {}, "keywordMap": {}, "tagMap": {}}],
            "blendShapeMaster": {"blendShapeGroups": [{
                "name": "Tint", "presetName": "unknown", "binds": [],
                "materialValues": [{"materialName": "Ball", "propertyName": "_Color", "targetValue": list(tint)}]}]}}}
        doc["extensionsUsed"] = ["VRM"]
    doc["materials"] = [material]
    return b.write_glb(path)
