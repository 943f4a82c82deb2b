"""gltf_check: a clean export has no problem; each structural fault planted in it is found and named."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from conftest import need_shared
from facepuppet.offline.io.gltf.write import build_gltf, encode_glb
from facepuppet.offline.io.gltf_check import check_gltf, check_gltf_bytes
from helpers.gltf_characters import parts_character


@pytest.fixture(scope="module")
def vrm0():
    doc, blob, _ = build_gltf(parts_character(), "vrm0")
    return doc, bytes(blob)


def glb(doc, blob) -> bytes:
    return encode_glb(doc, blob)


def problems(doc, blob) -> list[str]:
    return check_gltf_bytes(glb(doc, blob))


def changed(vrm0, change):
    doc, blob = vrm0
    doc = json.loads(json.dumps(doc))
    blob = bytearray(blob)
    change(doc, blob)
    return problems(doc, bytes(blob))


def test_the_clean_export_has_no_problem(vrm0, tmp_path):
    assert problems(*vrm0) == []
    path = tmp_path / "ok.vrm"
    path.write_bytes(glb(*vrm0))
    assert check_gltf(path) == []


def test_a_misaligned_chunk_is_found(vrm0):
    doc, blob = vrm0
    js = json.dumps(doc).encode()
    js += b" " * ((-len(js) % 4) + 1)  # one byte too many: length 4k+1, so the BIN chunk starts unaligned
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob
    data = struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body
    found = check_gltf_bytes(data)
    assert any(p.startswith("GLB chunk 0.chunkLength") and "multiple of 4" in p for p in found)
    assert any(p.startswith("GLB chunk 1") and "not 4-byte aligned" in p for p in found)


def test_a_wrong_header_length_and_a_truncated_file_are_found(vrm0):
    data = glb(*vrm0)
    assert any("header.length" in p for p in check_gltf_bytes(data[:-8]))
    assert any("run past the end" in p for p in check_gltf_bytes(data[:-8]))
    wrong_version = data[:4] + struct.pack("<I", 1) + data[8:]
    assert any("version" in p for p in check_gltf_bytes(wrong_version))


def test_a_bin_chunk_shorter_than_the_buffer_is_found(vrm0):
    found = changed(vrm0, lambda d, b: d["buffers"][0].update(byteLength=len(b) + 64))
    assert any(p.startswith("buffers[0].byteLength") for p in found)


def test_an_accessor_past_its_buffer_view_is_found(vrm0):
    def grow(doc, blob):
        doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]]["count"] += 5
    found = changed(vrm0, grow)
    assert any("elements of 12 bytes" in p and "need" in p for p in found), found


def test_a_byte_stride_is_taken_into_account(vrm0):
    def stride(doc, blob):  # 8 normals at a stride of 16 need 7 * 16 + 12 = 124 bytes; the view has 96
        acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]]
        doc["bufferViews"][acc["bufferView"]]["byteStride"] = 16
    found = changed(vrm0, stride)
    assert any("stride 16" in p for p in found), found


def test_a_buffer_view_past_its_buffer_is_found(vrm0):
    found = changed(vrm0, lambda d, b: d["bufferViews"][0].update(byteOffset=len(b)))
    assert any(p.startswith("bufferViews[0]") and "byteLength" in p for p in found)


def test_wrong_min_max_and_missing_min_max_are_found(vrm0):
    def shift(doc, blob):
        acc = doc["accessors"][doc["meshes"][1]["primitives"][0]["attributes"]["POSITION"]]
        acc["max"][0] += 0.01
    found = changed(vrm0, shift)
    assert any(".max" in p and "the data's max" in p for p in found), found

    def drop(doc, blob):
        del doc["accessors"][doc["meshes"][1]["primitives"][0]["targets"][0]["POSITION"]]["min"]
    found = changed(vrm0, drop)
    assert any("targets[0].POSITION" in p and "needs min and max" in p for p in found), found


def test_an_index_past_the_vertex_count_is_found(vrm0):
    def poke(doc, blob):
        prim = doc["meshes"][0]["primitives"][0]
        acc = doc["accessors"][prim["indices"]]
        view = doc["bufferViews"][acc["bufferView"]]
        n = doc["accessors"][prim["attributes"]["POSITION"]]["count"]
        struct.pack_into("<H", blob, view["byteOffset"] + 2, n)  # one index = the vertex count
    found = changed(vrm0, poke)
    assert any("meshes[0].primitives[0].indices" in p and "past the vertex count 8" in p for p in found), found


def test_mismatched_morph_target_counts_are_found(vrm0):
    found = changed(vrm0, lambda d, b: d["meshes"][1]["primitives"][1]["targets"].pop())
    assert any("morph target counts differ" in p and "[3, 2]" in p for p in found), found


def test_skin_joints_and_joint_indices_are_checked(vrm0):
    found = changed(vrm0, lambda d, b: d["skins"][0]["joints"].__setitem__(0, 999))
    assert any(p.startswith("skins[0].joints[0]") for p in found)

    def fewer(doc, blob):  # drop the last joint: JOINTS_0 of the face (the head) points past the list
        doc["skins"][0]["joints"].pop()
    found = changed(vrm0, fewer)
    assert any("JOINTS_0" in p and "joints" in p for p in found), found


def test_texture_image_and_sampler_references_are_checked(vrm0):
    found = changed(vrm0, lambda d, b: d["textures"][0].update(source=7, sampler=9))
    assert "textures[0].source: 7 is not an index into images (2 entries)" in found
    assert any(p.startswith("textures[0].sampler") for p in found)
    found = changed(vrm0, lambda d, b: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(index=5))
    assert any(p.startswith("materials[0].pbrMetallicRoughness.baseColorTexture.index") for p in found)


def test_vrm_references_are_checked(vrm0):
    def bad(doc, blob):
        vrm = doc["extensions"]["VRM"]
        vrm["humanoid"]["humanBones"][0]["node"] = 500
        vrm["blendShapeMaster"]["blendShapeGroups"][0]["binds"][0]["index"] = 40
        vrm["firstPerson"]["firstPersonBone"] = 77
    found = changed(vrm0, bad)
    assert any("humanoid.humanBones[0].node" in p for p in found)
    assert any("blendShapeGroups[0].binds[0].index" in p and "morph targets" in p for p in found)
    assert any("firstPersonBone" in p for p in found)
    doc, blob, _ = build_gltf(parts_character(source_format="vrm1"), "vrm1")
    doc["extensions"]["VRMC_vrm"]["expressions"]["preset"]["blink"]["morphTargetBinds"][0]["node"] = 0  # no mesh
    del doc["extensions"]["VRMC_vrm"]["meta"]["authors"]
    found = problems(doc, blob)
    assert any("morphTargetBinds[0].node" in p and "has no mesh" in p for p in found), found
    assert "extensions.VRMC_vrm.meta.authors: missing (required)" in found


def test_sparse_indices_must_increase(vrm0):
    def swap(doc, blob):
        for acc in doc["accessors"]:
            s = acc.get("sparse")
            if s and s["count"] >= 2:
                view = doc["bufferViews"][s["indices"]["bufferView"]]
                a, b2 = struct.unpack_from("<HH", blob, view["byteOffset"])
                struct.pack_into("<HH", blob, view["byteOffset"], b2, a)
                return
        raise AssertionError("no sparse accessor with two indices in the export")
    found = changed(vrm0, swap)
    assert any("strictly increasing" in p for p in found), found


@pytest.mark.data
def test_the_data_kit_files_pass():
    files = sorted(need_shared("gltf").glob("*.*"))
    files = [f for f in files if f.suffix in (".vrm", ".glb", ".gltf")]
    assert files
    for f in files:
        assert check_gltf(f) == [], f.name


def test_required_fields_are_named():
    doc = {"asset": {}, "buffers": [{}], "accessors": [{"count": 1, "type": "VEC5", "componentType": 1}]}
    found = check_gltf_bytes(json.dumps(doc).encode())
    assert "asset.version: missing (required)" in found
    assert "buffers[0].byteLength: missing (required)" in found
    assert any(p.startswith("accessors[0].componentType") for p in found)
    assert any(p.startswith("accessors[0].type") for p in found)
    assert check_gltf_bytes(b"\xff\xfe not json") == [
        "JSON: not UTF-8 JSON ('utf-8' codec can't decode byte 0xff in position 0: invalid start byte)"]
    assert np.all([isinstance(p, str) for p in found])


def test_nan_in_the_json_is_not_json(tmp_path):
    path = tmp_path / "nan.gltf"
    path.write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [], "weights": [0.5, NaN, -Infinity]}]}')
    problems = check_gltf(path)
    assert problems == ["meshes[0].weights[1]: NaN is not a JSON number (RFC 8259 has no NaN or Infinity)",
                        "meshes[0].weights[2]: -Infinity is not a JSON number (RFC 8259 has no NaN or Infinity)"]


def test_the_importers_structure_limits_are_listed_by_check_gltf(tmp_path):
    from facepuppet.offline.io.gltf.structure_limits import MAX_NODES

    path = tmp_path / "many.gltf"
    nodes = [{"name": "n"} for _ in range(MAX_NODES + 1)]
    path.write_text(json.dumps({"asset": {"version": "2.0"}, "nodes": nodes}))
    problems = check_gltf(path)
    assert problems == [f"nodes: {MAX_NODES + 1} nodes; a file may have at most {MAX_NODES} (beyond what "
                        "facepuppet imports)"]
