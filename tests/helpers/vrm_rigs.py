"""A small VRM 1.0 avatar written in code: a face, two eye bones with pupils, bone look-at, a spring chain.

Written with tests/helpers/gltf_writer.py (independent of the project's reader and writer), for the look-at
and spring bone import and drawing tests. The avatar faces +Z, its head at 1.5 m:

* node 0 ``hips`` (root) → 1 ``head`` (the face: a white 0.3 m square at z = 0.07) → 2 ``leftEye`` and
  3 ``rightEye`` (at x = ±0.05, z = 0.03, each with a black 2 cm pupil 5 cm in front of it, so a turn of the eye
  moves the pupil by centimetres), and 4 ``hair0`` → 5 ``hair1`` → 6 ``hair2`` behind the head (the spring);
* ``lookAt``: type bone, every range map 90° → 90° (an eye turns as far as the gaze);
* ``VRMC_springBone``: one spring over hair0, hair1, hair2 and a sphere and a capsule collider on the head.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.gltf_writer import GltfBuilder

IDENTITY_MAP = {"inputMaxValue": 90.0, "outputScale": 90.0}


def _square(b: GltfBuilder, cx: float, cy: float, z: float, half: float, material: int) -> dict:
    pos = np.array([[cx - half, cy - half, z], [cx + half, cy - half, z], [cx + half, cy + half, z],
                    [cx - half, cy + half, z]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    return {"primitives": [{"attributes": {"POSITION": b.accessor(pos, minmax=True)},
                            "indices": b.accessor(idx), "material": material}]}


def look_at_vrm(path: Path, *, look_at: dict | None = None, springs: dict | None = None) -> Path:
    """Write the avatar to ``path`` (a .vrm, GLB); ``look_at`` / ``springs`` replace its lookAt and
    VRMC_springBone objects (for tests of malformed ones)."""
    b = GltfBuilder()
    b.doc["materials"] = [
        {"name": "face", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]},
         "extensions": {"KHR_materials_unlit": {}}},
        {"name": "pupil", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]},
         "extensions": {"KHR_materials_unlit": {}}}]
    b.doc["meshes"] = [_square(b, 0.0, 0.05, 0.07, 0.15, 0), _square(b, 0.0, 0.0, 0.05, 0.01, 1),
                       _square(b, 0.0, 0.0, 0.05, 0.01, 1)]
    b.doc["nodes"] = [
        {"name": "hips", "children": [1]},
        {"name": "head", "translation": [0, 1.5, 0], "mesh": 0, "children": [2, 3, 4]},
        {"name": "leftEye", "translation": [0.05, 0.05, 0.03], "mesh": 1},
        {"name": "rightEye", "translation": [-0.05, 0.05, 0.03], "mesh": 2},
        {"name": "hair0", "translation": [0, 0.1, -0.05], "children": [5]},
        {"name": "hair1", "translation": [0, 0, -0.1], "children": [6]},
        {"name": "hair2", "translation": [0, 0, -0.1]},
    ]
    b.doc["scenes"], b.doc["scene"] = [{"nodes": [0]}], 0
    b.doc["extensionsUsed"] = ["VRMC_vrm", "VRMC_springBone", "KHR_materials_unlit"]
    look = {"type": "bone", "offsetFromHeadBone": [0, 0.05, 0], "rangeMapHorizontalInner": IDENTITY_MAP,
            "rangeMapHorizontalOuter": IDENTITY_MAP, "rangeMapVerticalDown": IDENTITY_MAP,
            "rangeMapVerticalUp": IDENTITY_MAP}
    spring = {"specVersion": "1.0",
              "colliders": [{"node": 1, "shape": {"sphere": {"offset": [0, 0.05, 0], "radius": 0.12}}},
                            {"node": 1, "shape": {"capsule": {"offset": [-0.1, 0.0, -0.1], "tail": [0.1, 0.0, -0.1],
                                                              "radius": 0.02}}}],
              "colliderGroups": [{"name": "head", "colliders": [0, 1]}],
              "springs": [{"name": "hair", "colliderGroups": [0],
                           "joints": [{"node": 4, "stiffness": 1.5, "dragForce": 0.3, "gravityPower": 0.2,
                                       "gravityDir": [0, -1, 0], "hitRadius": 0.01},
                                      {"node": 5, "stiffness": 1.0}, {"node": 6}]}]}
    b.doc["extensions"] = {
        "VRMC_vrm": {"specVersion": "1.0", "meta": {"name": "Eyes", "authors": ["facepuppet tests"],
                                                    "licenseUrl": "https://vrm.dev/licenses/1.0/"},
                     "humanoid": {"humanBones": {"hips": {"node": 0}, "head": {"node": 1}, "leftEye": {"node": 2},
                                                 "rightEye": {"node": 3}}},
                     "lookAt": look if look_at is None else look_at},
        "VRMC_springBone": spring if springs is None else springs,
    }
    return b.write_glb(path)
