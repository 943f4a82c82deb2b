"""glTF / GLB / VRM reader on small files written here (tests/helpers/gltf_writer.py), against hand-computed values."""

from __future__ import annotations

import io
import json
import struct
import warnings

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import ALPHA_MODES, LINEAR, NEAREST, REPEAT, SHADING

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf_container import GltfError
from helpers.gltf_writer import GltfBuilder, write_glb

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)


def triangle(b: GltfBuilder, positions=TRI, *, node: dict | None = None, prim: dict | None = None,
             mesh: dict | None = None) -> dict:
    """One mesh with one primitive over ``positions`` on one node of the default scene; returns the primitive."""
    p = {"attributes": {"POSITION": b.accessor(np.asarray(positions), minmax=True)}, **(prim or {})}
    b.doc["meshes"] = [{"name": "tri", "primitives": [p], **(mesh or {})}]
    b.doc["nodes"] = [{"mesh": 0, **(node or {})}]
    b.doc["scenes"] = [{"nodes": [0]}]
    b.doc["scene"] = 0
    return p


def glb(tmp_path, b: GltfBuilder, name="t.glb"):
    return b.write_glb(tmp_path / name)


# -- accessors ------------------------------------------------------------------


def test_sparse_accessor_over_a_buffer_view_substitutes_the_listed_elements(tmp_path):
    b = GltfBuilder()
    view = b.view(TRI.tobytes())
    sparse = b.sparse(np.array([2], np.uint16), np.array([[0, 2, 0]], np.float32))
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": b.accessor(None, kind="VEC3", dtype="float32",
                                                                               view=view, count=3,
                                                                               sparse=sparse)}}]}]
    b.doc["nodes"], b.doc["scenes"] = [{"mesh": 0}], [{"nodes": [0]}]
    c = read_gltf(glb(tmp_path, b))
    np.testing.assert_array_equal(c.vertices, [[0, 0, 0], [1, 0, 0], [0, 2, 0]])


def test_sparse_accessor_without_a_buffer_view_is_zeros_plus_the_substitutions(tmp_path):
    b = GltfBuilder()
    sparse = b.sparse(np.array([1], np.uint8), np.array([[0, 0, 0.5]], np.float32))
    delta = b.accessor(None, kind="VEC3", dtype="float32", count=3, sparse=sparse)
    triangle(b, prim={"targets": [{"POSITION": delta}]}, mesh={"extras": {"targetNames": ["puff"]}})
    c = read_gltf(glb(tmp_path, b))
    assert c.shape_names == ("puff",)
    np.testing.assert_array_equal(c.dense_deltas()[0], [[0, 0, 0], [0, 0, 0.5], [0, 0, 0]])
    # no NORMAL in the file: normals are computed, and lifting vertex 1 tilts the whole triangle's normal
    assert len(c.delta_indices) == 3 and np.linalg.norm(c.delta_normals, axis=1).min() > 0.1


def test_quantized_normalized_and_integer_accessors(tmp_path):
    b = GltfBuilder()
    b.doc["extensionsUsed"] = b.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    pos = b.accessor(np.array([[0, 0, 0], [32767, 0, 0], [0, -32767, 0]], np.int16), normalized=True)
    uv = b.accessor(np.array([[255, 0], [0, 255], [51, 102]], np.uint8), normalized=True)
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv}}]},
                       {"primitives": [{"attributes": {"POSITION": b.accessor(
                           np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]], np.uint16))}}]}]
    b.doc["nodes"] = [{"mesh": 0, "scale": [2, 2, 2]}, {"mesh": 1, "scale": [0.01, 0.01, 0.01]}]
    b.doc["scenes"] = [{"nodes": [0, 1]}]
    c = read_gltf(glb(tmp_path, b))
    np.testing.assert_allclose(c.vertices[:3], [[0, 0, 0], [2, 0, 0], [0, -2, 0]], atol=1e-6)
    np.testing.assert_allclose(c.vertices[3:], [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], atol=1e-7)
    np.testing.assert_allclose(c.look.uv[:3], [[1, 0], [0, 1], [0.2, 0.4]], atol=1e-6)


def test_interleaved_byte_strided_buffer_view(tmp_path):
    b = GltfBuilder()
    normals = np.array([[0, 0, 1], [0, 1, 0], [1, 0, 0]], np.float32)
    interleaved = np.hstack([TRI, normals]).astype(np.float32)  # 24 bytes per vertex
    view = b.view(interleaved.tobytes(), stride=24)
    pos = b.accessor(None, kind="VEC3", dtype="float32", view=view, count=3)
    nrm = b.accessor(None, kind="VEC3", dtype="float32", view=view, offset=12, count=3)
    # a target that turns vertex 0's normal from +z to +x: its stored normal delta is (1, 0, -1) only if
    # the base normals were read through the stride
    dn = b.accessor(np.array([[1, 0, -1], [0, 0, 0], [0, 0, 0]], np.float32))
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm},
                                        "targets": [{"NORMAL": dn}]}]}]
    b.doc["nodes"], b.doc["scenes"] = [{"mesh": 0}], [{"nodes": [0]}]
    c = read_gltf(glb(tmp_path, b))
    np.testing.assert_array_equal(c.vertices, TRI)
    np.testing.assert_array_equal(c.delta_indices, [0])
    np.testing.assert_allclose(c.delta_normals, [[1, 0, -1]], atol=1e-6)


def test_data_uri_buffer_and_external_bin_decode_the_same(tmp_path):
    for how in ("data", "external"):
        b = GltfBuilder()
        triangle(b, positions=TRI + np.float32(3))
        path = b.write_gltf(tmp_path / f"{how}.gltf", external="tri data.bin" if how == "external" else None)
        c = read_gltf(path)
        np.testing.assert_array_equal(c.vertices, TRI + 3)
        assert c.source["format"] == "gltf"
    assert "%20" not in json.dumps(json.loads((tmp_path / "external.gltf").read_text())["buffers"])


@pytest.mark.parametrize("uri,why", [("../outside.bin", "inside the folder"), ("/etc/passwd", "inside the folder"),
                                     ("http://127.0.0.1/x.bin", "not URLs"), ("missing.bin", "cannot read")])
def test_external_buffer_outside_the_folder_a_url_or_missing_is_refused(tmp_path, uri, why):
    (tmp_path / "outside.bin").write_bytes(TRI.tobytes())
    sub = tmp_path / "model"
    sub.mkdir()
    b = GltfBuilder()
    triangle(b)
    path = b.write_gltf(sub / "m.gltf")
    doc = json.loads(path.read_text())
    doc["buffers"][0]["uri"] = uri
    path.write_text(json.dumps(doc))
    with pytest.raises(GltfError, match=rf"m\.gltf: buffers\[0\]\.uri: .*{why}"):
        read_gltf(path)


# -- nodes and skins ----------------------------------------------------------------


def test_node_transforms_through_the_hierarchy_and_parents_first_renumbering(tmp_path):
    b = GltfBuilder()
    triangle(b)
    s = np.sqrt(0.5)
    # file order: the mesh's node 0 is the child of node 1; node 2 is a matrix node (translate z 5)
    b.doc["nodes"] = [{"mesh": 0, "name": "child", "rotation": [0, 0, s, s], "scale": [2, 2, 2]},
                      {"name": "parent", "translation": [1, 0, 0], "children": [0, 2]},
                      {"name": "m", "mesh": 0,
                       "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1]}]
    b.doc["scenes"] = [{"nodes": [1]}]
    c = read_gltf(glb(tmp_path, b))
    # child: v -> scale 2 -> 90 deg about z -> + (1, 0, 0): (1,0,0) -> (2,0,0) -> (0,2,0) -> (1,2,0)
    np.testing.assert_allclose(c.vertices[:3], [[1, 0, 0], [1, 2, 0], [-1, 0, 0]], atol=1e-6)
    np.testing.assert_allclose(c.vertices[3:], TRI + [1, 0, 5], atol=1e-6)
    assert c.skeleton.names == ("parent", "child", "m")
    assert c.source["node_from_file"] == [1, 0, 2]
    np.testing.assert_array_equal(c.skeleton.parent, [-1, 0, 0])
    assert (c.skeleton.vertex_nodes[:3, 0] == 1).all() and (c.skeleton.vertex_weights[:, 0] == 1).all()
    assert c.layout.mesh_names == ("tri", "tri#2")


def test_scene_choice_scene_then_scene0_then_roots(tmp_path):
    b = GltfBuilder()
    triangle(b)
    b.doc["nodes"].append({"mesh": 0, "translation": [0, 0, 9]})
    b.doc["scenes"] = [{"nodes": [0]}, {"nodes": [1]}]
    b.doc["scene"] = 1
    assert read_gltf(glb(tmp_path, b)).vertices[0, 2] == 9
    del b.doc["scene"]
    assert read_gltf(glb(tmp_path, b)).n_vertices == 3 and read_gltf(glb(tmp_path, b)).vertices[0, 2] == 0
    del b.doc["scenes"]
    assert read_gltf(glb(tmp_path, b)).n_vertices == 6


def test_skinned_vertices_are_stored_at_the_rest_pose_with_normalized_weights(tmp_path):
    b = GltfBuilder()
    # joints: j0 at the origin, j1 translated (0, 1, 0); inverse bind matrices identity: each joint's
    # skinning matrix at rest is its world transform, so vertex 1 (all on j1) rises by 1
    prim = triangle(b)
    prim["attributes"]["JOINTS_0"] = b.accessor(np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]], np.uint8))
    prim["attributes"]["WEIGHTS_0"] = b.accessor(np.array([[128, 128, 0, 0], [255, 0, 0, 0], [0, 0, 0, 0]],
                                                          np.uint8), normalized=True)
    ibm = b.accessor(np.tile(np.eye(4, dtype=np.float32).T.reshape(1, 16), (2, 1)), kind="MAT4")
    b.doc["nodes"] = [{"mesh": 0, "skin": 0}, {"name": "j0", "children": [2]}, {"name": "j1", "translation": [0, 1, 0]}]
    b.doc["skins"] = [{"joints": [1, 2], "inverseBindMatrices": ibm}]
    b.doc["scenes"] = [{"nodes": [0, 1]}]
    c = read_gltf(glb(tmp_path, b))
    np.testing.assert_allclose(c.vertices, [[0, 0.5, 0], [1, 1, 0], [0, 1, 0]], atol=1e-6)
    k = c.skeleton
    j1 = k.names.index("j1")
    np.testing.assert_allclose(k.vertex_weights[0, :2], [0.5, 0.5])  # 128/255 each, renormalised
    assert k.vertex_nodes[1, 0] == j1 and k.vertex_weights[1, 0] == 1
    assert k.vertex_nodes[2, 0] == k.names.index("j0") and k.vertex_weights[2, 0] == 1  # no weight: first joint
    assert any("without weight" in w for w in c.source["warnings"])


def test_missing_normals_are_computed_and_non_indexed_and_u8_u32_indices(tmp_path):
    for dtype in (None, np.uint8, np.uint32):
        b = GltfBuilder()
        quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
        prim = triangle(b, positions=quad if dtype else quad[[0, 1, 2, 0, 2, 3]])
        if dtype:
            prim["indices"] = b.accessor(np.array([0, 1, 2, 0, 2, 3], dtype))
        c = read_gltf(glb(tmp_path, b))
        np.testing.assert_array_equal(c.triangles, [[0, 1, 2], [0, 2, 3]] if dtype else [[0, 1, 2], [3, 4, 5]])


def test_colors_u16_vec4_and_materials_textures_samplers(tmp_path):
    b = GltfBuilder()
    prim = triangle(b)
    prim["attributes"]["COLOR_0"] = b.accessor(np.array([[65535, 0, 0, 65535], [0, 65535, 0, 0],
                                                         [0, 0, 13107, 1]], np.uint16), normalized=True)
    prim["attributes"]["TEXCOORD_0"] = b.accessor(np.zeros((3, 2), np.float32))
    png = io.BytesIO()
    Image.fromarray(np.array([[[255, 0, 0, 255], [0, 0, 255, 128]]], np.uint8), "RGBA").save(png, "PNG")
    jpg = io.BytesIO()
    Image.fromarray(np.full((8, 8, 3), 200, np.uint8), "RGB").save(jpg, "JPEG", quality=95)
    (tmp_path / "grey.jpg").write_bytes(jpg.getvalue())
    b.doc["images"] = [{"bufferView": b.view(png.getvalue()), "mimeType": "image/png", "name": "px"},
                       {"uri": "grey.jpg"}]
    b.doc["samplers"] = [{"magFilter": NEAREST, "minFilter": LINEAR, "wrapS": REPEAT}]
    b.doc["textures"] = [{"source": 0, "sampler": 0}, {"source": 1}]
    b.doc["materials"] = [
        {"name": "a", "alphaMode": "MASK", "alphaCutoff": 0.3, "doubleSided": True, "emissiveFactor": [0.1, 0, 0],
         "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1, 1], "baseColorTexture": {
             "index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0], "rotation": 0.25,
                                                                   "scale": [2, 3]}}}},
         "extensions": {"KHR_materials_unlit": {}}},
        {"name": "b", "alphaMode": "BLEND", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}},
         "emissiveFactor": [0.5, 0.25, 0], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}}]
    prim["material"] = 0
    b.doc["meshes"][0]["primitives"].append(dict(prim, material=1))
    b.doc["extensionsUsed"] = ["KHR_materials_unlit", "KHR_texture_transform"]
    # a .gltf beside its JPEG (the image URI is relative to the file)
    c = read_gltf(b.write_gltf(tmp_path / "m.gltf"))
    np.testing.assert_allclose(c.vertex_color, [[1, 0, 0], [0, 1, 0], [0, 0, 0.2]], atol=1e-6)
    lk = c.look
    np.testing.assert_allclose(lk.base_color, [[0.5, 0.25, 1, 1], [1, 1, 1, 1]])
    np.testing.assert_allclose(lk.alpha, [[ALPHA_MODES["MASK"], 0.3], [ALPHA_MODES["BLEND"], 0.5]])
    assert lk.shading[0, 0] == SHADING["unlit"] and lk.shading[0, 1] == 1 and lk.shading[1, 0] == SHADING["lit"]
    np.testing.assert_allclose(lk.emissive, [[0.1, 0, 0], [2, 1, 0]])  # factor x KHR_materials_emissive_strength
    np.testing.assert_allclose(lk.uv_transform[0], [0.5, 0, 0.25, 2, 3])
    np.testing.assert_allclose(lk.uv_transform[1], [0, 0, 0, 1, 1])
    assert lk.texture_names == ("px", "image1") and list(lk.texture) == [0, 1]
    np.testing.assert_array_equal(lk.image(0), [[[255, 0, 0, 255], [0, 0, 255, 128]]])
    assert abs(int(lk.image(1)[4, 4, 0]) - 200) <= 3 and lk.image(1).shape == (8, 8, 4)
    assert list(lk.texture_info[0, 3:]) == [NEAREST, LINEAR, REPEAT, 0]
    assert list(c.triangle_material) == [0, 1] and c.layout.primitives[:, 5].tolist() == [0, 1]
    # two primitives over the same attributes share one vertex list
    assert c.n_vertices == 3 and c.layout.primitives[:, :2].tolist() == [[0, 3], [0, 3]]


# -- morph targets ---------------------------------------------------------------------


def test_targets_named_per_primitive_or_mesh_one_shape_across_meshes(tmp_path):
    b = GltfBuilder()
    d = b.accessor(np.array([[0, 0, 1], [0, 0, 0], [0, 0, 0]], np.float32))
    d2 = b.accessor(np.array([[0, 0, 0], [0, 0, 2], [0, 0, 0]], np.float32))
    pos = b.accessor(TRI)
    b.doc["meshes"] = [
        {"name": "m0", "extras": {"targetNames": ["mesh-level", "x"]}, "primitives": [
            {"attributes": {"POSITION": pos}, "targets": [{"POSITION": d}, {"POSITION": d2}],
             "extras": {"targetNames": ["jawOpen", "smile"]}}]},
        {"name": "m1", "primitives": [{"attributes": {"POSITION": pos},
                                       "targets": [{"POSITION": d}, {"POSITION": d2}]}],
         "extras": {"targetNames": ["jawOpen"]}, "weights": [0.25, 0]}]
    b.doc["nodes"] = [{"mesh": 0}, {"mesh": 1}]
    b.doc["scenes"] = [{"nodes": [0, 1]}]
    c = read_gltf(glb(tmp_path, b))
    assert c.shape_names == ("jawOpen", "smile", "m1.1")
    d0 = c.dense_deltas()
    np.testing.assert_array_equal(d0[0, [0, 3], 2], [1, 1])  # one shape spanning both meshes
    assert np.count_nonzero(d0[0]) == 2 and d0[2, 4, 2] == 2
    assert c.source["default_weights"] == {"jawOpen": 0.25}


def test_a_file_without_morph_targets_is_a_character_with_zero_shapes(tmp_path):
    b = GltfBuilder()
    triangle(b)
    c = read_gltf(glb(tmp_path, b))
    assert c.n_shapes == 0
    c.save(tmp_path / "c.npz")
    assert Character.load(tmp_path / "c.npz").n_shapes == 0


# -- VRM -----------------------------------------------------------------------------------


def vrm_triangle(b: GltfBuilder, version: int) -> None:
    d = b.accessor(np.array([[0, 0, 0], [0, 0.5, 0], [0, 0, 0]], np.float32))
    e = b.accessor(np.array([[0.5, 0, 0], [0, 0, 0], [0, 0, 0]], np.float32))
    triangle(b, positions=TRI + np.float32([0, 0, 2]), prim={"targets": [{"POSITION": d}, {"POSITION": e}]},
             mesh={"extras": {"targetNames": ["blink_l", "grin"]}}, node={"name": "face"})
    b.doc["nodes"][0]["children"] = [1]
    b.doc["nodes"] += [{"name": "headbone", "translation": [0, 1.5, 0]}]


def test_vrm0_turned_to_face_plus_z_with_presets_custom_binds_humanoid_meta(tmp_path):
    b = GltfBuilder()
    vrm_triangle(b, 0)
    b.doc["extensionsUsed"] = ["VRM"]
    b.doc["extensions"] = {"VRM": {
        "meta": {"title": "Tri", "author": "Someone", "licenseName": "CC0", "version": "1"},
        "humanoid": {"humanBones": [{"bone": "head", "node": 1}]},
        "blendShapeMaster": {"blendShapeGroups": [
            {"name": "Blink_L", "presetName": "blink_l", "binds": [{"mesh": 0, "index": 0, "weight": 100}]},
            {"name": "smirk", "presetName": "unknown", "isBinary": True,
             "binds": [{"mesh": 0, "index": 1, "weight": 50}, {"mesh": 0, "index": 0, "weight": 25}]},
            {"name": "Joy", "presetName": "joy", "binds": []}]}}}
    c = read_gltf(glb(tmp_path, b, "t.vrm"))
    assert c.source["format"] == "vrm0" and c.source["turned_y180"] is True
    np.testing.assert_allclose(c.vertices, [[0, 0, -2], [-1, 0, -2], [0, 1, -2]], atol=1e-6)  # (x, y, z) -> (-x, y, -z)
    np.testing.assert_allclose(c.dense_deltas()[1, 0], [-0.5, 0, 0], atol=1e-6)
    e = c.expressions
    assert e.names == ("Blink_L", "smirk", "Joy") and e.presets == ("Blink_L", "", "Joy")
    s, w = e.binds(1)
    assert dict(zip(s.tolist(), w.tolist())) == {1: 0.5, 0: 0.25}
    assert e.flags[1].tolist() == [1, 0, 0, 0] and len(e.binds(2)[0]) == 0
    head = c.skeleton.bones["head"]
    assert c.skeleton.names[head] == "headbone"
    np.testing.assert_allclose(c.pivot, [0, 1.5, 0], atol=1e-6)
    assert c.credits == "Tri by Someone, CC0"
    assert c.source["vrm_extension"]["meta"]["title"] == "Tri"


def test_vrm1_expressions_overrides_humanoid_mtoon_not_turned(tmp_path):
    b = GltfBuilder()
    vrm_triangle(b, 1)
    b.doc["materials"] = [{"name": "skin", "extensions": {"VRMC_materials_mtoon": {
        "specVersion": "1.0", "shadeColorFactor": [0.2, 0.1, 0.3], "shadingShiftFactor": -0.2,
        "shadingToonyFactor": 0.8}}}]
    b.doc["meshes"][0]["primitives"][0]["material"] = 0
    b.doc["extensionsUsed"] = ["VRMC_vrm", "VRMC_materials_mtoon", "EXT_something_else"]
    b.doc["extensions"] = {"VRMC_vrm": {
        "specVersion": "1.0", "meta": {"name": "Tri1", "authors": ["A", "B"], "licenseUrl": "https://x/l"},
        "humanoid": {"humanBones": {"head": {"node": 1}}},
        "expressions": {"preset": {"aa": {"morphTargetBinds": [{"node": 0, "index": 1, "weight": 0.7}],
                                          "overrideBlink": "block", "overrideMouth": "blend"},
                                   "surprised": {}},
                        "custom": {"smirk": {"isBinary": True,
                                             "morphTargetBinds": [{"node": 0, "index": 0, "weight": 1}]}}}}}
    c = read_gltf(glb(tmp_path, b, "t.vrm"))
    assert c.source["format"] == "vrm1" and not c.source["turned_y180"]
    np.testing.assert_allclose(c.vertices, TRI + [0, 0, 2], atol=1e-6)
    e = c.expressions
    assert e.names == ("A", "surprised", "smirk") and e.presets == ("A", "", "")
    assert e.flags.tolist() == [[0, 1, 0, 2], [0, 0, 0, 0], [1, 0, 0, 0]]
    s, w = e.binds(0)
    assert s.tolist() == [1] and w.tolist() == pytest.approx([0.7])
    np.testing.assert_allclose(c.look.shading[0, :7], [SHADING["toon"], 0, 0.2, 0.1, 0.3, -0.2, 0.8], atol=1e-6)
    assert c.credits == "Tri1 by A, B, https://x/l"
    assert any("EXT_something_else" in w for w in c.source["warnings"])


def test_vrm0_mtoon_shade_colour_and_range_in_vrm1_terms(tmp_path):
    b = GltfBuilder()
    vrm_triangle(b, 0)
    b.doc["materials"] = [{"name": "Flat"}, {"name": "Face"}, {"name": "Pbr"}]  # matched by name, not order
    b.doc["meshes"][0]["primitives"][0]["material"] = 0
    b.doc["extensions"] = {"VRM": {"materialProperties": [{
        "name": "Face", "shader": "VRM/MToon", "floatProperties": {"_ShadeShift": 0.0, "_ShadeToony": 0.9},
        "vectorProperties": {"_ShadeColor": [0.5, 1.0, 0.0, 1]}}, {"name": "Flat", "shader": "VRM/UnlitTexture"},
        {"name": "Pbr", "shader": "VRM_USE_GLTFSHADER"}]}}
    c = read_gltf(glb(tmp_path, b, "t.vrm"))
    assert c.look.shading[0, 0] == SHADING["unlit"] and c.look.shading[2, 0] == SHADING["lit"]
    row = c.look.shading[1]
    # 0.x range [shift, lerp(1, shift, toony)] = [0, 0.1]: toony (2 - 0.1) / 2 = 0.95, shift -0.05
    np.testing.assert_allclose(row[[0, 5, 6]], [SHADING["toon"], -0.05, 0.95], atol=1e-6)
    np.testing.assert_allclose(row[2:5], [((0.5 + 0.055) / 1.055) ** 2.4, 1.0, 0.0], atol=1e-6)  # sRGB -> linear


# -- refusals ---------------------------------------------------------------------------


def good_glb(tmp_path) -> tuple[dict, bytes]:
    b = GltfBuilder()
    prim = triangle(b)
    prim["indices"] = b.accessor(np.array([0, 1, 2], np.uint16))
    return dict(b.doc, buffers=[{"byteLength": len(b.blob)}]), b.padded_blob()


def forged(tmp_path, change) -> object:
    doc, blob = good_glb(tmp_path)
    doc = json.loads(json.dumps(doc))
    new = change(doc, blob)
    blob = new if isinstance(new, bytes) else blob
    return write_glb(tmp_path / "bad.glb", doc, blob)


def test_required_extensions_we_cannot_honour_are_refused_by_name_used_only_is_a_warning(tmp_path):
    def req(doc, _):
        doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_draco_mesh_compression", "EXT_meshopt_compression"]
    with pytest.raises(GltfError, match=r"bad\.glb: extensionsRequired: KHR_draco_mesh_compression, "
                                        r"EXT_meshopt_compression: required"):
        read_gltf(forged(tmp_path, req))

    def used(doc, _):
        doc["extensionsUsed"] = ["KHR_texture_basisu"]
    assert read_gltf(forged(tmp_path, used)).source["warnings"] == [
        "extensions used but not honoured (ignored): KHR_texture_basisu"]


BAD_DOCS = {
    "mode": (lambda d, b: d["meshes"][0]["primitives"][0].update(mode=1),
             r"meshes\[0\]\.primitives\[0\]\.mode: 1 \(lines\): only triangle lists"),
    "accessor past its view": (lambda d, b: d["accessors"][0].update(count=4),
                               r"accessors\[0\]\.count: 4 elements .* need 48 bytes but bufferView 0 has 36"),
    "view past buffer": (lambda d, b: d["bufferViews"][1].update(byteLength=400),
                         r"bufferViews\[1\]: bytes 36\.\.436 run past the end of buffer 0"),
    "buffer longer than the BIN chunk": (lambda d, b: d["buffers"][0].update(byteLength=4000),
                                         r"buffers\[0\]\.byteLength: 4000 bytes declared but the GLB BIN chunk"),
    "index past vertices": (lambda d, b: b[:36] + struct.pack("<HHH", 0, 1, 3) + b[42:],
                            r"meshes\[0\]\.primitives\[0\]\.indices: index 3 is past the primitive's 3 vertices"),
    "NaN position": (lambda d, b: struct.pack("<f", float("nan")) + b[4:],
                     r"meshes\[0\]\.primitives\[0\]\.attributes\.POSITION: vertex 0 is \[nan"),
    "gigabytes": (lambda d, b: d["accessors"][0].update(count=400_000_000),
                  r"accessors\[0\]\.count: 400000000 elements is more than"),
    "gigabytes within limit": (lambda d, b: d["accessors"][0].update(count=40_000_000),
                               r"accessors\[0\]\.count: 40000000 elements .* but bufferView 0 has 36"),
    "missing componentType": (lambda d, b: d["accessors"][0].pop("componentType"),
                              r"accessors\[0\]\.componentType: missing"),
    "missing accessors": (lambda d, b: d.pop("accessors"), r"meshes\[0\]\.primitives\[0\]\.attributes\.POSITION: "
                                                           r"0 is not an index into accessors"),
    "bad index type": (lambda d, b: d["meshes"][0]["primitives"][0]["attributes"].update(POSITION="0"),
                       r"meshes\[0\]\.primitives\[0\]\.attributes\.POSITION: '0' is not an index into accessors"),
}


@pytest.mark.parametrize("case", sorted(BAD_DOCS))
def test_bad_fields_are_refused_naming_file_and_field(tmp_path, case):
    change, message = BAD_DOCS[case]
    with pytest.raises(GltfError, match=rf"{tmp_path}/bad\.glb: {message}"):
        read_gltf(forged(tmp_path, change))


def test_bad_containers_are_refused(tmp_path):
    doc, blob = good_glb(tmp_path)
    good = write_glb(tmp_path / "good.glb", doc, blob).read_bytes()
    (jlen,) = struct.unpack_from("<I", good, 12)
    cases = {
        "truncated": (good[:-10], r"GLB header\.length: says \d+ bytes but the file has \d+ \(truncated\)"),
        "header only": (good[:8], r"GLB header: truncated"),
        "chunk length": (good[:12] + struct.pack("<I", jlen + 4000) + good[16:],
                         r"GLB chunk 0\.chunkLength: \d+ bytes from byte 20 run past the end"),
        "chunk type": (good[:16] + struct.pack("<I", 0x12345678) + good[20:],
                       r"GLB chunk 0\.chunkType: the first chunk must be JSON"),
        "not utf-8": (good[:20] + b"\xff\xfe" + good[22:], r"JSON chunk: not UTF-8"),
        "not json": (good[:20] + b"[[[" + good[23:], r"JSON chunk: not valid JSON"),
        "version": (good[:4] + struct.pack("<I", 1) + good[8:], r"GLB header\.version: 1"),
    }
    for name, (data, message) in cases.items():
        path = tmp_path / f"{name}.glb"
        path.write_bytes(data)
        with pytest.raises(GltfError, match=message) as info:
            read_gltf(path)
        assert str(path) in str(info.value), name


def test_cli_import_rig_reads_gltf_prints_summary_and_refuses_bad_files_writing_nothing(tmp_path, capsys):
    b = GltfBuilder()
    vrm_triangle(b, 0)
    b.doc["extensions"] = {"VRM": {"meta": {"title": "Tri", "author": "Someone", "licenseName": "CC_BY"},
                                   "humanoid": {"humanBones": [{"bone": "head", "node": 1}]}}}
    src = glb(tmp_path, b, "t.vrm")
    out = tmp_path / "c.npz"
    assert main(["import-rig", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "3 vertices, 1 triangles" in text and "shapes: 2" in text and "credits: Tri by Someone, CC BY" in text
    assert "humanoid head, neck (not found)" in text and "VRM meta: title=Tri" in text
    assert Character.load(out).n_shapes == 2
    bad = forged(tmp_path, lambda d, b: d["accessors"][0].update(count=4))
    out2 = tmp_path / "never.npz"
    assert main(["import-rig", str(bad), "-o", str(out2)]) == 2
    assert "bad.glb: accessors[0].count:" in capsys.readouterr().err
    assert list(tmp_path.glob("never*")) == []
    assert main(["import-rig", str(src), str(tmp_path), "-o", str(out2)]) == 2  # a shapes folder makes no sense
    assert not out2.exists()


def test_cli_import_rig_obj_without_a_shapes_folder_is_a_character_without_shapes(tmp_path, capsys):
    (tmp_path / "head.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert main(["import-rig", str(tmp_path / "head.obj"), "-o", str(tmp_path / "head.npz")]) == 0
    assert Character.load(tmp_path / "head.npz").n_shapes == 0


@pytest.mark.parametrize("case", ["translation", "cutoff", "sampler"])
def test_numbers_beyond_float32_or_int32_are_refused_without_numpy_warnings(tmp_path, case):
    # found by the file fuzz: a 1e300 translation overflowed in the matrix product (RuntimeWarning), a
    # 1e300 alphaCutoff in the float32 cast, a 20-digit sampler code was an OverflowError traceback
    b = GltfBuilder()
    prim = triangle(b)
    if case == "translation":
        b.doc["nodes"] = [{"children": [1], "translation": [1e300, 0, 0]}, {"mesh": 0, "scale": [1e300, 1, 1]}]
        want = r"nodes: the node transforms"
    else:
        png = io.BytesIO()
        Image.fromarray(np.zeros((1, 1, 4), np.uint8), "RGBA").save(png, "PNG")
        b.doc.update(images=[{"bufferView": b.view(png.getvalue())}], textures=[{"source": 0, "sampler": 0}],
                     samplers=[{"magFilter": 99999999999999999999 if case == "sampler" else 9728}],
                     materials=[{"alphaCutoff": 1e300 if case == "cutoff" else 0.5,
                                 "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}])
        prim["material"] = 0
        want = r"samplers\[0\]\.magFilter: 99999999999999999999 is not one of" if case == "sampler" else \
            r"materials: values beyond the float32 range"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(GltfError, match=want):
            read_gltf(glb(tmp_path, b))


def test_a_rotated_joint_turns_positions_morph_deltas_and_normal_deltas(tmp_path):
    # joint turned +90 degrees about +Y, (x, y, z) -> (z, y, -x); identity inverse bind: the rest pose turns
    b = GltfBuilder()
    s = float(np.sqrt(0.5))
    prim = triangle(b)
    prim["attributes"]["NORMAL"] = b.accessor(np.tile(np.float32([0, 0, 1]), (3, 1)))
    prim["attributes"]["JOINTS_0"] = b.accessor(np.zeros((3, 4), np.uint16))
    prim["attributes"]["WEIGHTS_0"] = b.accessor(np.tile(np.float32([1, 0, 0, 0]), (3, 1)))
    prim["targets"] = [{"POSITION": b.accessor(np.array([[1, 0, 0], [0, 0, 0], [0, 0, 0]], np.float32)),
                        "NORMAL": b.accessor(np.array([[0, 1, -1], [0, 0, 0], [0, 0, 0]], np.float32))}]
    b.doc["nodes"] = [{"mesh": 0, "skin": 0}, {"name": "j", "rotation": [0, s, 0, s]}]
    b.doc["skins"] = [{"joints": [1]}]
    b.doc["scenes"] = [{"nodes": [0, 1]}]
    c = read_gltf(glb(tmp_path, b))
    np.testing.assert_allclose(c.vertices, [[0, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-6)
    np.testing.assert_array_equal(c.delta_indices, [0])
    np.testing.assert_allclose(c.delta_positions, [[0, 0, -1]], atol=1e-6)
    # normal (0, 0, 1) -> (1, 0, 0); with the target's delta (0, 1, 0) -> (0, 1, 0): delta (-1, 1, 0)
    np.testing.assert_allclose(c.delta_normals, [[-1, 1, 0]], atol=1e-6)


def test_computed_normals_of_shared_vertices_use_every_primitive_over_them(tmp_path):
    # two primitives (two materials) over one quad's four vertices; a target lifts vertex 3 in z, which
    # only the second primitive's triangle touches: its normals turn, so normal deltas are stored there
    b = GltfBuilder()
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    pos = b.accessor(quad)
    lift = b.accessor(np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0.5]], np.float32))
    prims = [{"attributes": {"POSITION": pos}, "targets": [{"POSITION": lift}], "material": m,
              "indices": b.accessor(np.array(t, np.uint16))} for m, t in ((0, [0, 1, 2]), (1, [0, 2, 3]))]
    b.doc.update(meshes=[{"primitives": prims}], nodes=[{"mesh": 0}], scenes=[{"nodes": [0]}],
                 materials=[{"name": "a"}, {"name": "b"}])
    c = read_gltf(glb(tmp_path, b))
    assert c.n_vertices == 4
    turned = set(c.delta_indices[np.linalg.norm(c.delta_normals, axis=1) > 0.1].tolist())
    assert turned == {0, 2, 3}  # the second triangle's corners (vertex 1 is only on the first, flat one)
