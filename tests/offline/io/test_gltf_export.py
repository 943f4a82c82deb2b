"""export-character: a character with skeleton, look, expressions and layout written as GLB / glTF / VRM 0.x / 1.0.

Each file is checked by gltf_check and read back independently: pygltflib parses it, the
accessors are decoded here with NumPy (tests/helpers/gltf_characters.decode), PNGs with
Pillow, and the values compared with the character's (turned 180° about +Y for VRM 0.x).
"""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.model.character import Character

from conftest import need_shared
from facepuppet.offline.io.gltf import read as gltf_read
from facepuppet.offline.io.gltf.write import ExportError, export_character
from facepuppet.offline.io.gltf_check import check_gltf
from helpers.gltf_characters import BONES, decode, node_worlds, parts_character, view_bytes

TABLES_V1 = Path(__file__).resolve().parents[2] / "runtime" / "files" / "data" / "tables_v1" / "character.npz"
TURN = np.array([-1.0, 1.0, -1.0])
SUFFIX = {"glb": ".glb", "gltf": ".gltf", "vrm0": ".vrm", "vrm1": ".vrm"}


def write(tmp_path, fmt, character=None, **kw):
    c = character if character is not None else parts_character(**kw)
    out = tmp_path / f"out_{fmt}{SUFFIX[fmt]}"
    summary = export_character(c, out, vrm=int(fmt[3]) if fmt.startswith("vrm") else None)
    return c, out, summary


def load(path: Path):
    if path.suffix == ".gltf":
        g = pygltflib.GLTF2().load_json(str(path))
        blob = base64.b64decode(g.buffers[0].uri.split(",", 1)[1])
    else:  # .glb and .vrm: pygltflib picks its loader by suffix and knows only .glb as binary
        g = pygltflib.GLTF2().load_binary(str(path))
        blob = g.binary_blob()
    return g, blob


def frame(fmt: str) -> np.ndarray:
    return TURN if fmt == "vrm0" else np.ones(3)


@pytest.mark.parametrize("fmt", ["glb", "gltf", "vrm0", "vrm1"])
def test_export_passes_the_structural_check(tmp_path, fmt):
    _, out, summary = write(tmp_path, fmt)
    assert check_gltf(out) == []
    assert summary.n_meshes == 2 and summary.n_primitives == 3 and summary.n_textures == 2


@pytest.mark.parametrize("fmt", ["glb", "gltf", "vrm0", "vrm1"])
def test_vertices_and_morph_deltas_read_back(tmp_path, fmt):
    c, out, _ = write(tmp_path, fmt, units="cm")  # cm: written in metres
    g, blob = load(out)
    dense = c.dense_deltas() * 0.01
    dense_n = c.dense_deltas(normals=True)
    prims = c.layout.primitives
    assert [m.name for m in g.meshes] == ["Body", "Face"]
    k = 0
    for m, mesh in enumerate(g.meshes):
        names = mesh.extras["targetNames"]
        for prim in mesh.primitives:
            first, n = int(prims[k, 0]), int(prims[k, 1])
            assert int(prims[k, 4]) == m and prim.material == int(prims[k, 5])
            pos = decode(g, blob, prim.attributes.POSITION)
            np.testing.assert_allclose(pos, c.vertices[first:first + n] * 0.01 * frame(fmt), atol=1e-6)
            tri = decode(g, blob, prim.indices).reshape(-1, 3) + first
            t0, nt = int(prims[k, 2]), int(prims[k, 3])
            np.testing.assert_array_equal(tri, c.triangles[t0:t0 + nt])
            assert len(prim.targets) == len(names)  # the same targets on every primitive of the mesh
            for t, name in enumerate(names):
                s = c.shape_names.index(name)
                dp = decode(g, blob, prim.targets[t]["POSITION"])
                dn = decode(g, blob, prim.targets[t]["NORMAL"])
                np.testing.assert_allclose(dp, dense[s, first:first + n] * frame(fmt), atol=1e-7)
                np.testing.assert_allclose(dn, dense_n[s, first:first + n] * frame(fmt), atol=1e-7)
            k += 1
    # which shapes each mesh has: those that move its vertices; Spanning on both; Still kept on the first
    assert g.meshes[0].extras["targetNames"] == ["Spanning", "Still"]
    assert g.meshes[1].extras["targetNames"] == ["Blink", "jawOpen", "Spanning"]


@pytest.mark.parametrize("fmt", ["glb", "vrm0", "vrm1"])
def test_skin_weights_joints_and_rest_pose(tmp_path, fmt):
    c, out, _ = write(tmp_path, fmt)
    g, blob = load(out)
    k = c.skeleton
    assert [n.name for n in g.nodes[:k.n_nodes]] == list(k.names)
    skin = g.skins[0]
    world = node_worlds(g)
    ibm = decode(g, blob, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    # joint matrices at rest are the identity (vertices stored in the world rest pose)
    for j, node in enumerate(skin.joints):
        np.testing.assert_allclose(world[node] @ ibm[j], np.eye(4), atol=1e-5)
    # node rest transforms: the character's (turned for VRM 0.x), through the hierarchy
    t = np.diag([*frame(fmt), 1.0])
    np.testing.assert_allclose(world[:k.n_nodes], t @ k.global_transforms(), atol=1e-5)
    assert g.nodes[k.names.index("hat")].matrix is not None  # the sheared node as a matrix
    assert g.nodes[k.names.index("neck")].rotation is not None and g.nodes[k.names.index("neck")].scale is not None
    want = np.zeros((c.n_vertices, k.n_nodes))
    np.add.at(want, (np.repeat(np.arange(c.n_vertices), 4), k.vertex_nodes.reshape(-1).astype(int)),
              k.vertex_weights.reshape(-1))
    got = np.zeros_like(want)
    seen = set()
    for mesh_node in [n for n in g.nodes[k.n_nodes:] if n.mesh is not None]:  # (a VRM 1.0 adds spring tails)
        assert mesh_node.skin == 0
        for p, prim in enumerate(g.meshes[mesh_node.mesh].primitives):
            row = [r for r in c.layout.primitives if r[4] == mesh_node.mesh][p]
            first, n = int(row[0]), int(row[1])
            if (first, n) in seen:
                continue
            seen.add((first, n))
            joints = decode(g, blob, prim.attributes.JOINTS_0).astype(int)
            weights = decode(g, blob, prim.attributes.WEIGHTS_0)
            nodes = np.asarray(skin.joints)[joints]
            for i in range(4):
                np.add.at(got, (np.arange(first, first + n), nodes[:, i]), weights[:, i])
    np.testing.assert_allclose(got, want, atol=1e-6)


@pytest.mark.parametrize("fmt", ["glb", "vrm1"])
def test_textures_and_materials_read_back(tmp_path, fmt):
    c, out, _ = write(tmp_path, fmt)
    g, blob = load(out)
    for t in range(2):
        img = g.images[g.textures[t].source]
        assert img.mimeType == "image/png"
        pixels = np.asarray(Image.open(io.BytesIO(view_bytes(g, blob, img.bufferView))).convert("RGBA"))
        np.testing.assert_array_equal(pixels, c.look.image(t))  # lossless
    s0 = g.samplers[g.textures[0].sampler]
    assert (s0.magFilter, s0.minFilter, s0.wrapS, s0.wrapT) == (9729, 9987, 10497, 33071)
    m0, m1, m2 = g.materials
    assert m0.pbrMetallicRoughness.baseColorTexture.index == 0
    tt = m0.pbrMetallicRoughness.baseColorTexture.extensions["KHR_texture_transform"]
    np.testing.assert_allclose([*tt["offset"], tt["rotation"], *tt["scale"]], [0.1, 0.2, 0, 0.5, 0.5], atol=1e-6)
    np.testing.assert_allclose(m0.pbrMetallicRoughness.baseColorFactor, [1, 0.9, 0.8, 1], atol=1e-6)
    assert (m1.alphaMode, m1.doubleSided) == ("MASK", True) and m1.alphaCutoff == pytest.approx(0.3)
    assert m2.alphaMode == "BLEND" and "KHR_materials_unlit" in m2.extensions
    np.testing.assert_allclose(m2.emissiveFactor, [0.2, 0.1, 0], atol=1e-6)
    if fmt == "vrm1":
        mt = m1.extensions["VRMC_materials_mtoon"]
        np.testing.assert_allclose(mt["shadeColorFactor"], [0.4, 0.2, 0.3], atol=1e-6)
        assert mt["shadingShiftFactor"] == pytest.approx(-0.1) and mt["shadingToonyFactor"] == pytest.approx(0.8)


def test_vrm0_toon_material_properties_give_back_the_stored_shading_range(tmp_path):
    # the character keeps VRM 1.0's terms; 0.x's range [shift, 1 + (shift - 1) toony] must have their centre/width
    c, out, _ = write(tmp_path, "vrm0")
    g, _ = load(out)
    props = {p["name"]: p for p in g.extensions["VRM"]["materialProperties"]}
    toon = props["toon"]
    assert toon["shader"] == "VRM/MToon" and toon["floatProperties"]["_CullMode"] == 0.0
    shift, toony = toon["floatProperties"]["_ShadeShift"], toon["floatProperties"]["_ShadeToony"]
    lo, hi = shift, 1 + (shift - 1) * toony
    assert -(lo + hi) / 2 == pytest.approx(-0.1) and (2 - (hi - lo)) / 2 == pytest.approx(0.8)
    shade = np.asarray(toon["vectorProperties"]["_ShadeColor"][:3])  # sRGB in the file
    linear = np.where(shade <= 0.04045, shade / 12.92, ((shade + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(linear, [0.4, 0.2, 0.3], atol=1e-6)
    assert props["blush"]["shader"] == "VRM/UnlitTransparent" and props["skin"]["shader"] == "VRM_USE_GLTFSHADER"
    # Unity's _MainTex ST counts v from the bottom: offset v = 1 - scale v - offset v (glTF)
    assert props["blush"]["textureProperties"] == {"_MainTex": 1}


def test_vrm0_expressions_humanoid_meta_and_kept_extension(tmp_path):
    c, out, summary = write(tmp_path, "vrm0")
    g, _ = load(out)
    vrm = g.extensions["VRM"]
    assert vrm["specVersion"] == "0.0"
    assert vrm["meta"]["title"] == "Quad" and vrm["meta"]["licenseName"] == "CC_BY" and "texture" not in vrm["meta"]
    bones = {b["bone"]: b["node"] for b in vrm["humanoid"]["humanBones"]}
    assert bones == {name: j for j, (name, _, _) in enumerate(BONES)} and vrm["humanoid"]["armStretch"] == 0.05
    groups = {grp["name"]: grp for grp in vrm["blendShapeMaster"]["blendShapeGroups"]}
    body, face = (g.meshes[i].extras["targetNames"] for i in range(2))
    assert groups["Blink"]["presetName"] == "blink"
    assert groups["Blink"]["binds"] == [{"mesh": 1, "index": face.index("Blink"), "weight": 100.0}]
    a = groups["A"]
    assert a["presetName"] == "a" and a["isBinary"] is True
    assert sorted((b["mesh"], b["index"], b["weight"]) for b in a["binds"]) == [
        (0, body.index("Spanning"), 50.0), (1, face.index("Spanning"), 50.0)]  # a shape on two meshes
    smirk = groups["Smirk"]
    assert smirk["presetName"] == "unknown"
    assert sorted((b["index"], b["weight"]) for b in smirk["binds"]) == sorted(
        [(face.index("jawOpen"), 25.0), (face.index("Blink"), 75.0)])
    # perfect sync: jawOpen is one of ARKit's 52 and has no expression of its name: a custom JawOpen
    assert groups["JawOpen"]["presetName"] == "unknown" and groups["JawOpen"]["binds"] == [
        {"mesh": 1, "index": face.index("jawOpen"), "weight": 100.0}]
    assert summary.added_expressions == ["JawOpen"] and "Still" not in groups and "Spanning" not in groups
    # the raw extension's node indices (file order 2 s + 1) remapped to the written nodes
    head, hat = c.skeleton.names.index("head"), c.skeleton.names.index("hat")
    assert vrm["firstPerson"]["firstPersonBone"] == head and vrm["firstPerson"]["meshAnnotations"] == []
    sec = vrm["secondaryAnimation"]
    assert sec["boneGroups"][0]["bones"] == [hat] and sec["boneGroups"][0]["colliderGroups"] == [0]
    assert [cg["node"] for cg in sec["colliderGroups"]] == [head]
    assert any("meshAnnotations" in w for w in summary.warnings)


def test_vrm1_expressions_overrides_meta_humanoid(tmp_path):
    c, out, _ = write(tmp_path, "vrm1", source_format="vrm1")
    g, _ = load(out)
    vrm = g.extensions["VRMC_vrm"]
    assert vrm["specVersion"] == "1.0"
    assert vrm["meta"] == {"name": "Quad", "authors": ["Someone"], "licenseUrl": "https://example.org/l"}
    assert vrm["humanoid"]["humanBones"]["head"] == {"node": c.skeleton.names.index("head")}
    assert vrm["lookAt"] == {"type": "bone", "offsetFromHeadBone": [0, 0.06, 0]}
    ex = vrm["expressions"]
    assert set(ex["preset"]) == {"blink", "aa"} and set(ex["custom"]) == {"Smirk", "JawOpen"}
    assert ex["preset"]["aa"]["isBinary"] is True
    smirk = ex["custom"]["Smirk"]
    assert (smirk["overrideBlink"], smirk["overrideLookAt"], smirk["overrideMouth"]) == ("block", "none", "blend")
    for e in [*ex["preset"].values(), *ex["custom"].values()]:
        for b in e["morphTargetBinds"]:
            mesh = g.meshes[g.nodes[b["node"]].mesh]
            assert 0 <= b["index"] < len(mesh.extras["targetNames"]) and 0 <= b["weight"] <= 1
    blink = ex["preset"]["blink"]["morphTargetBinds"]
    assert len(blink) == 1 and g.meshes[g.nodes[blink[0]["node"]].mesh].name == "Face"
    weights = sorted(b["weight"] for b in smirk["morphTargetBinds"])
    assert weights == pytest.approx([0.25, 0.75])


def test_vrm0_from_a_plus_z_character_is_turned(tmp_path):
    c = parts_character(source_format="vrm1")  # a VRM 1.0 character faces +Z
    _, out, summary = write(tmp_path, "vrm0", character=c)
    g, blob = load(out)
    assert summary.turned_y180
    pos = decode(g, blob, g.meshes[0].primitives[0].attributes.POSITION)
    np.testing.assert_allclose(pos, c.vertices[:8] * TURN, atol=1e-6)
    assert g.extensions["VRM"]["meta"]["title"] == "Quad" and g.extensions["VRM"]["meta"]["author"] == "Someone"


@pytest.mark.parametrize("fmt", ["glb", "gltf", "vrm0", "vrm1"])
def test_trimesh_loads_the_file(tmp_path, fmt):
    c, out, _ = write(tmp_path, fmt)
    scene = trimesh.load(str(out), file_type="glb" if fmt.startswith("vrm") else None, process=False)
    counts = sorted(len(geom.vertices) for geom in scene.geometry.values())
    assert counts == sorted(int(p[1]) for p in c.layout.primitives)
    assert sum(len(geom.faces) for geom in scene.geometry.values()) == len(c.triangles)


def test_an_obj_character_exports_as_a_glb_with_vertex_colours(tmp_path):
    c = Character.load(TABLES_V1)
    assert c.skeleton is None and c.layout is None
    _, out, summary = write(tmp_path, "glb", character=c)
    assert check_gltf(out) == []
    g, blob = load(out)
    assert len(g.meshes) == 1 and not g.skins
    used = sorted(set(c.triangle_material.tolist()))
    prims = g.meshes[0].primitives
    assert [p.material for p in prims] == used  # one primitive per material
    scale = {"m": 1, "cm": 0.01, "mm": 0.001}[c.units]
    np.testing.assert_allclose(decode(g, blob, prims[0].attributes.POSITION), c.vertices * scale, atol=1e-6)
    np.testing.assert_allclose(decode(g, blob, prims[0].attributes.COLOR_0), c.vertex_color, atol=1e-6)
    tri = np.vstack([decode(g, blob, p.indices).reshape(-1, 3) for p in prims])
    want = np.vstack([c.triangles[c.triangle_material == m] for m in used])
    np.testing.assert_array_equal(tri, want)
    assert g.meshes[0].extras["targetNames"] == list(c.shape_names)
    trimesh.load(str(out), process=False)


def test_an_obj_character_as_vrm_is_refused_naming_what_is_missing(tmp_path):
    c = Character.load(TABLES_V1)
    out = tmp_path / "x.vrm"
    with pytest.raises(ExportError, match=r"humanoid skeleton.*none.*hips, spine, head"):
        export_character(c, out)
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_skeleton_without_the_required_bones_is_refused_for_vrm(tmp_path):
    c = parts_character()
    k = c.skeleton
    c = c.with_parts(skeleton=type(k)(k.names, k.parent, k.rest_local, k.vertex_nodes, k.vertex_weights,
                                      {b: n for b, n in k.bones.items() if b not in ("leftFoot", "rightHand")}))
    with pytest.raises(ExportError, match="leftFoot, rightHand"):
        export_character(c, tmp_path / "x.vrm", vrm=1)


def test_suffix_and_vrm_option_are_checked(tmp_path):
    c = parts_character()
    with pytest.raises(ExportError, match="unknown output format"):
        export_character(c, tmp_path / "x.fbx")
    with pytest.raises(ExportError, match="only for a .vrm"):
        export_character(c, tmp_path / "x.glb", vrm=1)


def test_progress_is_reported_per_primitive(tmp_path):
    seen = []
    export_character(parts_character(), tmp_path / "x.glb", progress=lambda i, n, name: seen.append((i, n, name)))
    assert seen == [(1, 3, "Body"), (2, 3, "Face"), (3, 3, "Face")]


def test_cli_export_character_and_check_gltf(tmp_path, capsys):
    src = parts_character().save(tmp_path / "quad.npz")
    out = tmp_path / "quad.vrm"
    assert main(["export-character", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "VRM0" in text and "2 meshes, 3 primitives" in text and "1 added for perfect sync" in text
    assert "credits: Quad by Someone, CC BY" in text
    # an existing output is refused without --force, and left as it was
    before = out.read_bytes()
    assert main(["export-character", str(src), "-o", str(out), "--vrm", "1"]) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == before
    assert main(["export-character", str(src), "-o", str(out), "--vrm", "1", "--force"]) == 0
    assert json.loads(out.read_bytes()[20:20 + int.from_bytes(out.read_bytes()[12:16], "little")])[
        "extensions"]["VRMC_vrm"]["specVersion"] == "1.0"
    capsys.readouterr()
    assert main(["check-gltf", str(out)]) == 0
    assert "no structural problem" in capsys.readouterr().out
    bad = tmp_path / "bad.glb"
    bad.write_bytes(out.read_bytes()[:-4])
    assert main(["check-gltf", str(bad)]) == 2
    captured = capsys.readouterr()
    assert "GLB header.length" in captured.out and "structural problem" in captured.err


def test_the_ict_head_exports_as_a_glb_that_passes_the_check(ict_character, tmp_path):
    out = tmp_path / "ict.glb"
    summary = export_character(ict_character, out)
    assert check_gltf(out) == []
    assert summary.n_targets == ict_character.n_shapes and summary.n_sparse_targets > 0
    g, blob = load(out)
    names = g.meshes[0].extras["targetNames"]
    assert names == list(ict_character.shape_names)
    s = names.index("eyeBlink_L")
    prim = g.meshes[0].primitives[0]
    np.testing.assert_allclose(decode(g, blob, prim.targets[s]["POSITION"]),
                               ict_character.dense_deltas()[s] * 0.01, atol=1e-7)


def test_round_trip_import_export_import(tmp_path):
    for fmt, kw in (("vrm0", {}), ("vrm1", {"source_format": "vrm1"}), ("glb", {})):
        c, out, _ = write(tmp_path, fmt, **kw)
        back = gltf_read.read_gltf(out)
        assert back.source["format"] == ("glb" if fmt == "glb" else fmt)
        np.testing.assert_allclose(back.vertices, c.vertices, atol=1e-6)
        assert set(back.shape_names) == set(c.shape_names)
        order = [back.shape_names.index(n) for n in c.shape_names]
        np.testing.assert_allclose(back.dense_deltas()[order], c.dense_deltas(), atol=1e-6)
        # weights per (vertex, node): the reader renumbers nodes parents first, by name here
        back_node = [back.skeleton.names.index(n) for n in c.skeleton.names]
        want = np.zeros((c.n_vertices, len(back.skeleton.names)))
        got = np.zeros_like(want)
        for i in range(4):
            np.add.at(want, (np.arange(c.n_vertices), np.asarray(back_node)[c.skeleton.vertex_nodes[:, i]]),
                      c.skeleton.vertex_weights[:, i])
            np.add.at(got, (np.arange(c.n_vertices), back.skeleton.vertex_nodes[:, i]),
                      back.skeleton.vertex_weights[:, i])
        np.testing.assert_allclose(got, want, atol=1e-6)
        np.testing.assert_allclose(back.skeleton.global_transforms()[back_node], c.skeleton.global_transforms(),
                                   atol=1e-5)
        for t in range(2):
            np.testing.assert_array_equal(back.look.image(t), c.look.image(t))
        np.testing.assert_allclose(back.look.base_color, c.look.base_color, atol=1e-6)
        np.testing.assert_allclose(back.look.alpha, c.look.alpha, atol=1e-6)
        np.testing.assert_allclose(back.look.uv_transform, c.look.uv_transform, atol=1e-6)
        if fmt == "glb":
            continue
        np.testing.assert_allclose(back.look.shading[:, [0, 1]], c.look.shading[:, [0, 1]])
        np.testing.assert_allclose(back.look.shading[1, 2:7], c.look.shading[1, 2:7], atol=1e-5)
        assert back.skeleton.bones == {b: back_node[n] for b, n in c.skeleton.bones.items()}
        e, be = c.expressions, back.expressions
        assert be.names[:3] == e.names and be.names[3:] == ("JawOpen",)
        for i in (0, 2):  # Blink and Smirk: their shapes are on one mesh each
            s, w = e.binds(i)
            bs, bw = be.binds(i)
            assert dict(zip([back.shape_names[x] for x in bs], bw.tolist())) == pytest.approx(
                dict(zip([c.shape_names[x] for x in s], w.tolist())))
        np.testing.assert_array_equal(be.flags[:3, 0], e.flags[:, 0])
        if fmt == "vrm1":
            np.testing.assert_array_equal(be.flags[:3], e.flags)


def test_round_trip_keeps_the_bind_weight_of_a_shape_on_two_meshes(tmp_path):
    # VRM binds are per mesh: expression A binds Spanning at 0.5 on Body and on Face (two binds of 50 / 0.5);
    # read back, that is one shape at 0.5, not the sum of the two binds
    for fmt, kw in (("vrm0", {}), ("vrm1", {"source_format": "vrm1"})):
        c, out, _ = write(tmp_path, fmt, **kw)
        back = gltf_read.read_gltf(out)
        s, w = back.expressions.binds(back.expressions.names.index("A"))
        assert [back.shape_names[x] for x in s] == ["Spanning"] and w.tolist() == pytest.approx([0.5]), fmt


@pytest.mark.data
@pytest.mark.parametrize("name", ["Godette_vrm_v4.vrm", "subdivision_shapekey_modifier_vrm1.vrm"])
def test_round_trip_of_the_data_kit_avatars(tmp_path, name):
    # the kit's VRM 0.x (Godette) and VRM 1.0 avatars: import -> export (as they came) -> import gives the same
    path = need_shared("gltf", name)
    c = gltf_read.read_gltf(path)
    out = tmp_path / name
    summary = export_character(c, out)
    assert check_gltf(out) == []
    back = gltf_read.read_gltf(out)
    assert back.source["format"] == c.source["format"] and back.source["turned_y180"] == c.source["turned_y180"]
    assert summary.turned_y180 == (c.source["format"] == "vrm0")
    np.testing.assert_allclose(back.vertices, c.vertices, atol=1e-6)
    np.testing.assert_array_equal(back.triangles, c.triangles)
    assert back.shape_names == c.shape_names and back.material_names == c.material_names
    np.testing.assert_allclose(back.dense_deltas(), c.dense_deltas(), atol=1e-6)
    assert back.skeleton.names == c.skeleton.names and back.skeleton.bones == c.skeleton.bones
    np.testing.assert_allclose(back.skeleton.rest_local, c.skeleton.rest_local, atol=1e-5)
    np.testing.assert_array_equal(back.skeleton.vertex_nodes[c.skeleton.vertex_weights > 0],
                                  c.skeleton.vertex_nodes[c.skeleton.vertex_weights > 0])
    np.testing.assert_allclose(back.skeleton.vertex_weights, c.skeleton.vertex_weights, atol=1e-6)
    for t in range(len(c.look.texture_names)):
        np.testing.assert_array_equal(back.look.image(t), c.look.image(t))
    np.testing.assert_array_equal(back.look.texture_info, c.look.texture_info)
    for field in ("uv", "base_color", "emissive", "alpha", "shading", "texture", "uv_transform"):
        np.testing.assert_allclose(getattr(back.look, field), getattr(c.look, field), atol=1e-5, err_msg=field)
    # the expressions, and for perfect sync the shapes with ARKit names that had none
    n = c.expressions.n_expressions
    assert back.expressions.names[:n] == c.expressions.names
    np.testing.assert_allclose(back.expressions.dense(back.n_shapes)[:n], c.expressions.dense(c.n_shapes), atol=1e-6)
    np.testing.assert_array_equal(back.expressions.flags[:n], c.expressions.flags)
    assert list(back.expressions.names[n:]) == summary.added_expressions
    assert back.source["meta"] == c.source["meta"]  # the thumbnail too: its bytes are kept
    assert back.credits == c.credits


@pytest.mark.parametrize("fmt", ["vrm0", "vrm1"])
def test_meshes_go_back_on_the_nodes_that_held_them(tmp_path, fmt):
    # source.mesh_nodes: no new nodes; the first-person annotations follow their meshes
    c, out, summary = write(tmp_path, fmt, source_format=fmt, mesh_nodes=True)
    assert check_gltf(out) == [] and not [w for w in summary.warnings if "meshAnnotations" in w]
    g, _ = load(out)
    k = c.skeleton
    body, face = k.names.index("BodyNode"), k.names.index("FaceNode")
    assert len(g.nodes) == k.n_nodes
    assert (g.nodes[body].mesh, g.nodes[face].mesh, g.nodes[body].skin, g.nodes[face].skin) == (0, 1, 0, 0)
    assert sorted(g.scenes[0].nodes) == sorted(j for j in range(k.n_nodes) if k.parent[j] < 0)
    if fmt == "vrm0":
        annotations = g.extensions["VRM"]["firstPerson"]["meshAnnotations"]
        assert annotations == [{"mesh": 1, "firstPersonFlag": "ThirdPersonOnly"}]  # file mesh 0 is our Face
    else:
        vrm = g.extensions["VRMC_vrm"]
        assert vrm["firstPerson"]["meshAnnotations"] == [{"node": face, "type": "thirdPersonOnly"}]
        assert [b["node"] for b in vrm["expressions"]["preset"]["blink"]["morphTargetBinds"]] == [face]


def test_without_mesh_nodes_the_annotations_are_dropped_with_a_warning(tmp_path):
    _, out, summary = write(tmp_path, "vrm1", source_format="vrm1")
    g, _ = load(out)
    assert g.extensions["VRMC_vrm"]["firstPerson"]["meshAnnotations"] == []
    assert any("meshAnnotations" in w and "mesh_nodes" in w for w in summary.warnings)


def layered_rig() -> Character:
    """An OBJ-kind rig (cm): a skin sheet, an eye-occlusion card 0.2 cm in front of its middle, a lash card."""
    from helpers.small_characters import make_character

    xs = np.linspace(-4, 4, 9)
    sheet = np.array([(x, y, 0.0) for y in xs for x in xs], np.float32)
    i = np.arange(81).reshape(9, 9)
    a, b, c_, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    skin_t = np.vstack([np.c_[a, b, c_], np.c_[a, c_, d]])
    card = np.array([[-2, -1, 0.2], [2, -1, 0.2], [2, 1, 0.2], [-2, 1, 0.2]], np.float32)
    lash = card + np.float32([0, 2.5, 0.1])
    v = np.vstack([sheet, card, lash])
    t = np.vstack([skin_t, [[81, 82, 83], [81, 83, 84]], [[85, 86, 87], [85, 87, 88]]]).astype(np.uint32)
    mats = np.r_[np.zeros(len(skin_t)), [1, 1], [2, 2]]
    params = [[0.05, 18.0, 0, 0], [0.0, 1.0, 7, 0], [0.05, 10.0, 4, 0]]  # skin, occlusion, lashes
    colour = np.ones((len(v), 3), np.float32) * (0.9, 0.7, 0.6)
    return make_character(v, t, mats, colour, ("M_Skin", "M_EyeOcclusion", "M_Lashes"), params,
                          {"up": np.r_[np.zeros((81, 3)), np.tile([0, 0.5, 0], (8, 1))]})


def test_an_obj_rigs_thin_layers_export_see_through_and_their_kinds_come_back(tmp_path):
    from facepuppet.runtime.render.layers import vertex_opacity

    c = layered_rig()
    _, out, _ = write(tmp_path, "glb", character=c)
    assert check_gltf(out) == []
    g, blob = load(out)
    by_name = {m.name: m for m in g.materials}
    for name, kind in (("M_EyeOcclusion", "occlusion"), ("M_Lashes", "lashes")):
        m = by_name[name]
        assert m.alphaMode == "BLEND" and m.doubleSided, name
        assert m.extras["facepuppet"]["kind"] == kind
    assert by_name["M_Skin"].alphaMode in (None, "OPAQUE") and not by_name["M_Skin"].extras
    prim = g.meshes[0].primitives[0]
    assert g.accessors[prim.attributes.COLOR_0].type == "VEC4"
    rgba = decode(g, blob, prim.attributes.COLOR_0)
    np.testing.assert_allclose(rgba[:, :3], c.vertex_color, atol=1e-6)
    np.testing.assert_allclose(rgba[:81, 3], 1.0)              # the skin is opaque
    assert np.all(rgba[81:, 3] < 1.0)                          # the layers fade
    np.testing.assert_allclose(rgba[:, 3], vertex_opacity(c), atol=1e-6)  # as the OBJ path draws them
    back = gltf_read.read_gltf(out)
    np.testing.assert_array_equal(back.material_params[:, 2], c.material_params[:, 2])
    np.testing.assert_allclose(back.material_params[:, :2], c.material_params[:, :2])


def test_a_malformed_facepuppet_material_extra_is_warned_about_and_read_as_skin(tmp_path):
    c = layered_rig()
    out = tmp_path / "rig.gltf"
    export_character(c, out)
    doc = json.loads(out.read_text())
    doc["materials"][1]["extras"]["facepuppet"]["kind"] = "chrome"
    doc["materials"][2]["extras"]["facepuppet"]["shininess"] = "shiny"
    out.write_text(json.dumps(doc))
    back = gltf_read.read_gltf(out)
    warnings = [w for w in back.metadata["settings"]["source"]["warnings"] if "extras.facepuppet" in w]
    assert len(warnings) == 2 and "chrome" in warnings[0] and "shiny" in warnings[1]
    assert back.material_params[1, 2] == 0 and back.material_params[2, 2] == 0  # skin


@pytest.mark.gl
def test_the_imported_layers_are_drawn_see_through_over_the_skin(egl_ctx, tmp_path):
    from dataclasses import replace

    from facepuppet.runtime.render.renderer import FaceRenderer

    c = layered_rig()
    _, out, _ = write(tmp_path, "glb", character=c)
    back = gltf_read.read_gltf(out)
    opaque_alpha = np.array(back.look.alpha)
    opaque_alpha[:, 0] = 0  # every material OPAQUE: the cards hide the skin
    opaque = replace(back, look=replace(back.look, alpha=opaque_alpha))

    def centre_and_skin(character):
        r = FaceRenderer(egl_ctx, character, 160, 160, path="cpu", framing="body", log=lambda s: None)
        try:
            r.draw(np.zeros(character.n_shapes, np.float32))
            image = r.read_pixels().astype(int)
            k = {"m": 0.01, "cm": 1.0}[character.units]  # the rig was made in cm; glTF is in metres
            (cx, cy), (sx, sy) = r.project(np.array([[0, 0, 0.2], [0, -3, 0]]) * k).astype(int)
            return image[cy, cx], image[sy, sx]
        finally:
            r.close()

    layered, skin = centre_and_skin(back)
    hidden, _ = centre_and_skin(opaque)
    # the occlusion card darkens the skin it lies on, without hiding it as an opaque card does
    assert np.all(layered < skin - 10) and np.all(layered > hidden + 10)
