"""Exports checked by the Khronos glTF-Validator (the reference for a valid glTF 2.0 file).

Every data-kit file exported to each format it can take, and the characters the tests build, must give
0 errors and no warning code the original file did not have. One warning is inherent to a format, not to
the export: VRM 0.x's extension is named ``VRM``, without the vendor prefix and underscore glTF asks
(``INVALID_EXTENSION_NAME_FORMAT`` at ``/extensionsUsed``); every VRM 0.x file has it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.model.character import Character

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from helpers.gltf_characters import SHEARED, parts_character
from helpers.gltf_validator import ERROR, WARNING, codes, need_validator, problems, validate
from helpers.gltf_writer import GltfBuilder, glb_chunks

KIT_VRM = ["Godette_vrm_v4.vrm", "VRMC_materials_mtoon_UV_Animation_Test.vrm",
           "VRMC_vrm_expressions_isBinary_Overrides.vrm", "modifier_shapekey_vrm0.vrm",
           "pose_rotation_scale_shape_key_skinned.vrm", "simple_morph.vrm", "subdivision_shapekey_modifier_vrm1.vrm"]
KIT_GLTF = ["SimpleMorph.gltf"]
SUFFIX = {"glb": ".glb", "gltf": ".gltf", "vrm0": ".vrm", "vrm1": ".vrm"}
#: Warnings every file of a format has, whatever wrote it (see the module doc).
FORMAT_WARNINGS = {"vrm0": {"INVALID_EXTENSION_NAME_FORMAT"}}


def export(c, tmp_path: Path, fmt: str, stem: str = "out") -> Path:
    out = tmp_path / f"{stem}_{fmt}{SUFFIX[fmt]}"
    export_character(c, out, vrm=int(fmt[3]) if fmt.startswith("vrm") else None)
    return out


def check_against(original: dict, exported: dict, fmt: str) -> None:
    """0 errors, and only warning codes the original had (or its format always has)."""
    assert exported["numErrors"] == 0, problems(exported, ERROR)
    allowed = set(codes(original, WARNING)) | FORMAT_WARNINGS.get(fmt, set())
    new = [p for p in problems(exported, WARNING) if p.split(" ", 1)[0] not in allowed]
    assert not new, f"warnings the original did not have: {new}"


@pytest.mark.data
@pytest.mark.slow
@pytest.mark.parametrize("name", KIT_VRM + KIT_GLTF)
def test_every_kit_file_exports_valid_in_every_format(tmp_path, name):
    need_validator()
    path = need_shared("gltf", name)
    c = read_gltf(path)
    fmts = ["vrm0", "vrm1", "glb"] if name in KIT_VRM else ["glb", "gltf"]
    outs = [export(c, tmp_path, fmt) for fmt in fmts]
    original, *exported = validate(path, *outs)
    assert original["numErrors"] == 0
    for fmt, report in zip(fmts, exported):
        check_against(original, report, fmt)


@pytest.mark.parametrize("fmt", ["glb", "gltf", "vrm0", "vrm1"])
@pytest.mark.parametrize("mesh_nodes", [False, True])
def test_the_test_characters_export_valid(tmp_path, fmt, mesh_nodes):
    """The built character's one deliberate problem: its ``hat`` node has a sheared rest matrix, which glTF
    cannot say as TRS; the writer keeps it as a ``matrix`` (the exact rest pose), which the validator calls
    NODE_MATRIX_NON_TRS. Nothing else may be reported."""
    need_validator()
    c = parts_character(mesh_nodes=mesh_nodes)
    hat = c.skeleton.names.index(SHEARED)
    (report,) = validate(export(c, tmp_path, fmt))
    errors = [m for m in report["messages"] if m["severity"] == ERROR]
    assert [(m["code"], m["pointer"]) for m in errors] == [("NODE_MATRIX_NON_TRS", f"/nodes/{hat}/matrix")]
    assert set(codes(report, WARNING)) <= FORMAT_WARNINGS.get(fmt, set()), problems(report, WARNING)


def two_mesh_vrm1(tmp_path: Path) -> Path:
    """A VRM 1.0 the test builds: two unskinned meshes, each on a root node of its own (one turned 180° about
    +Y), a head with a three-joint hair chain and a sphere and a capsule collider, bone look-at with range maps,
    a toon material with a screen-space outline, an expression with a colour and a texture-transform bind."""
    b = GltfBuilder()
    quad = np.array([[-0.1, 0, 0], [0.1, 0, 0], [0.1, 0.2, 0], [-0.1, 0.2, 0]], np.float32)
    idx = b.accessor(np.array([0, 1, 2, 0, 2, 3], np.uint16))
    pos = b.accessor(quad, minmax=True)
    nrm = b.accessor(np.tile(np.float32([0, 0, 1]), (4, 1)))
    blink = b.accessor(np.array([[0, 0, 0], [0, 0, 0], [0, -0.1, 0], [0, -0.1, 0]], np.float32), minmax=True)
    b.doc["meshes"] = [{"name": f"m{k}", "extras": {"targetNames": ["blink"]},
                        "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm}, "indices": idx,
                                        "material": k, "targets": [{"POSITION": blink}]}]} for k in range(2)]
    b.doc["nodes"] = [
        {"name": "hips", "translation": [0, 1.0, 0], "children": [1]},
        {"name": "spine", "translation": [0, 0.2, 0], "children": [2]},
        {"name": "head", "translation": [0, 0.3, 0], "children": [3, 6, 7]},
        {"name": "hair1", "translation": [0, 0.1, -0.1], "children": [4]},
        {"name": "hair2", "translation": [0, -0.1, 0], "children": [5]},
        {"name": "hair3", "translation": [0, -0.1, 0]},
        {"name": "leftEye", "translation": [0.03, 0.05, 0.08]},
        {"name": "rightEye", "translation": [-0.03, 0.05, 0.08]},
        {"name": "face", "mesh": 0, "translation": [0, 1.5, 0.1]},
        {"name": "back", "mesh": 1, "translation": [0, 1.2, -0.1], "rotation": [0, 1, 0, 0]}]
    b.doc["scenes"] = [{"nodes": [0, 8, 9]}]
    b.doc["scene"] = 0
    limbs = {}
    for side, x in (("left", 1), ("right", -1)):
        for parent, chain, step in ((0, ("UpperLeg", "LowerLeg", "Foot"), [0.1 * x, -0.4, 0]),
                                    (1, ("UpperArm", "LowerArm", "Hand"), [0.2 * x, 0.2, 0])):
            for part in chain:
                n = len(b.doc["nodes"])
                b.doc["nodes"][parent].setdefault("children", []).append(n)
                b.doc["nodes"].append({"name": side + part, "translation": step})
                limbs[side + part] = {"node": n}
                parent = n
    outline = {"specVersion": "1.0", "shadeColorFactor": [0.5, 0.4, 0.4], "outlineWidthMode": "screenCoordinates",
               "outlineWidthFactor": 0.004, "outlineColorFactor": [0.1, 0.05, 0.0], "outlineLightingMixFactor": 0.5,
               "parametricRimColorFactor": [0.2, 0.2, 0.3], "parametricRimFresnelPowerFactor": 3.0}
    b.doc["materials"] = [{"name": "skin", "extensions": {"VRMC_materials_mtoon": outline}},
                          {"name": "cloth", "pbrMetallicRoughness": {"metallicFactor": 0.3, "roughnessFactor": 0.6}}]
    bone = {n: {"node": i} for i, n in enumerate(["hips", "spine", "head"])} | {
        "leftEye": {"node": 6}, "rightEye": {"node": 7}} | limbs
    ranges = {k: {"inputMaxValue": 90.0, "outputScale": s} for k, s in (
        ("rangeMapHorizontalInner", 8.0), ("rangeMapHorizontalOuter", 12.0), ("rangeMapVerticalDown", 10.0),
        ("rangeMapVerticalUp", 9.0))}
    b.doc["extensionsUsed"] = ["VRMC_vrm", "VRMC_springBone", "VRMC_materials_mtoon"]
    b.doc["extensions"] = {
        "VRMC_vrm": {"specVersion": "1.0",
                     "meta": {"name": "Two", "authors": ["T"], "licenseUrl": "https://vrm.dev/licenses/1.0/",
                              "allowRedistribution": True, "modification": "prohibited", "creditNotation": "required",
                              "commercialUsage": "personalNonProfit"},
                     "humanoid": {"humanBones": bone},
                     "firstPerson": {"meshAnnotations": [{"node": 8, "type": "thirdPersonOnly"}]},
                     "lookAt": {"type": "bone", "offsetFromHeadBone": [0.0, 0.06, 0.02], **ranges},
                     "expressions": {"preset": {
                         "sad": {"morphTargetBinds": [{"node": 8, "index": 0, "weight": 1.0}],
                                 "materialColorBinds": [{"material": 0, "type": "color",
                                                         "targetValue": [0.1, 0.2, 0.9, 1.0]}],
                                 "textureTransformBinds": [{"material": 0, "scale": [1, 1], "offset": [0.5, 0.0]}]}}}},
        "VRMC_springBone": {"specVersion": "1.0",
                            "colliders": [{"node": 2, "shape": {"sphere": {"offset": [0, 0.05, 0], "radius": 0.1}}},
                                          {"node": 1, "shape": {"capsule": {"offset": [0, 0, 0], "radius": 0.05,
                                                                            "tail": [0, 0.2, 0]}}}],
                            "colliderGroups": [{"name": "body", "colliders": [0, 1]}],
                            "springs": [{"name": "hair", "colliderGroups": [0], "joints": [
                                {"node": 3, "stiffness": 1.5, "dragForce": 0.3, "gravityPower": 0.2,
                                 "gravityDir": [0, -1, 0], "hitRadius": 0.01},
                                {"node": 4, "stiffness": 1.5, "dragForce": 0.3, "gravityPower": 0.2,
                                 "gravityDir": [0, -1, 0], "hitRadius": 0.01},
                                {"node": 5}]}]}}
    return b.write_glb(tmp_path / "two.vrm")


def test_a_built_unskinned_two_mesh_vrm1_exports_valid_and_keeps_its_parts(tmp_path):
    need_validator()
    path = two_mesh_vrm1(tmp_path)
    c = read_gltf(path)
    outs = {fmt: export(c, tmp_path, fmt) for fmt in ("vrm0", "vrm1", "glb")}
    original, *reports = validate(path, *outs.values())
    assert original["numErrors"] == 0
    for fmt, report in zip(outs, reports):
        check_against(original, report, fmt)
        doc = glb_chunks(outs[fmt].read_bytes())[0]
        assert "skins" not in doc  # unskinned meshes stay unskinned (no SKIN_NO_COMMON_ROOT)
    for fmt in ("vrm0", "vrm1"):  # in their nodes' frames in the file, where they were in the character
        back = read_gltf(outs[fmt])
        np.testing.assert_allclose(back.vertices, c.vertices, atol=1e-6)
        np.testing.assert_allclose(back.dense_deltas(), c.dense_deltas(), atol=1e-6)
        np.testing.assert_allclose(back.rest_normals(), c.rest_normals(), atol=1e-5)
    one = glb_chunks(outs["vrm1"].read_bytes())[0]
    names = [n.get("name") for n in one["nodes"]]
    spring = one["extensions"]["VRMC_springBone"]
    assert [[names[j["node"]] for j in s["joints"]] for s in spring["springs"]] == [["hair1", "hair2", "hair3"]]
    assert [names[c_["node"]] for c_ in spring["colliders"]] == ["head", "spine"]
    vrm = one["extensions"]["VRMC_vrm"]
    assert vrm["lookAt"]["rangeMapVerticalUp"] == {"inputMaxValue": 90.0, "outputScale": 9.0}
    assert vrm["expressions"]["preset"]["sad"]["materialColorBinds"][0]["targetValue"] == [0.1, 0.2, 0.9, 1.0]
    assert one["materials"][0]["extensions"]["VRMC_materials_mtoon"]["outlineWidthFactor"] == 0.004
    assert one["materials"][1]["pbrMetallicRoughness"] == {"metallicFactor": 0.3, "roughnessFactor": 0.6}
    # through VRM 0.x and back: the springs (one bone group), capsule as two spheres, look-at, binds, licence
    zero = glb_chunks(outs["vrm0"].read_bytes())[0]
    sec = zero["extensions"]["VRM"]["secondaryAnimation"]
    assert [[zero["nodes"][b_]["name"] for b_ in g["bones"]] for g in sec["boneGroups"]] == [["hair1"]]
    assert sec["boneGroups"][0]["stiffiness"] == 1.5 and len(sec["colliderGroups"]) == 2
    assert zero["extensions"]["VRM"]["meta"]["licenseName"] == "CC_BY_NC_ND"
    again = export(read_gltf(outs["vrm0"]), tmp_path, "vrm1", stem="again")
    (report,) = validate(again)
    assert report["numErrors"] == 0
    a = glb_chunks(again.read_bytes())[0]["extensions"]["VRMC_vrm"]
    assert a["lookAt"] == {**vrm["lookAt"]}
    assert a["expressions"]["preset"]["sad"]["materialColorBinds"][0]["targetValue"] == pytest.approx(
        [0.1, 0.2, 0.9, 1.0], abs=1e-6)
    assert {k: a["meta"][k] for k in ("allowRedistribution", "modification", "creditNotation", "commercialUsage")} \
        == {"allowRedistribution": True, "modification": "prohibited", "creditNotation": "required",
            "commercialUsage": "personalNonProfit"}


TABLES_V1 = Path(__file__).resolve().parents[2] / "runtime" / "files" / "data" / "tables_v1" / "character.npz"


@pytest.mark.parametrize("fmt", ["glb", "gltf"])
def test_an_obj_character_exports_valid(tmp_path, fmt):
    """An OBJ rig's character (no skeleton, no layout, vertex colours) as plain glTF: nothing reported."""
    need_validator()
    (report,) = validate(export(Character.load(TABLES_V1), tmp_path, fmt))
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, problems(report, ERROR) + problems(report, WARNING)


@pytest.mark.slow
def test_the_ict_head_exports_valid(ict_character, tmp_path):
    need_validator()
    (report,) = validate(export(ict_character, tmp_path, "glb"))
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, problems(report, ERROR) + problems(report, WARNING)
