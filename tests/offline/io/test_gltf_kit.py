"""The glTF reader on the data kit's real files (../shared/data/gltf), against values read here from their JSON."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.mapping.vrm_names import VRM0_PRESETS, VRM1_FROM_VRM0

from facepuppet.offline.io.gltf.read import read_gltf
from helpers.gltf_writer import raw_accessor, read_doc

pytestmark = pytest.mark.data

KIT = ["Godette_vrm_v4.vrm", "SimpleMorph.gltf", "modifier_shapekey_vrm0.vrm",
       "pose_rotation_scale_shape_key_skinned.vrm", "simple_morph.vrm", "subdivision_shapekey_modifier_vrm1.vrm"]


def kit(name):
    from conftest import need_shared

    return need_shared("gltf", name)


def scene_nodes(doc) -> list[int]:
    """The default scene's nodes, depth first, each parent before its children, in file order."""
    def visit(i):
        return [i] + [j for c in doc["nodes"][i].get("children", []) for j in visit(c)]

    return [j for r in doc["scenes"][doc.get("scene", 0)]["nodes"] for j in visit(r)]


def expected_counts(doc) -> dict:
    """Counts from the JSON alone: vertices (distinct attribute sets per mesh instance), target names,
    expressions with their bind counts, humanoid head/neck nodes, base colour textures."""
    import json

    n_v, names = 0, []
    for i in scene_nodes(doc):
        node = doc["nodes"][i]
        if "mesh" not in node:
            continue
        mesh = doc["meshes"][node["mesh"]]
        seen = set()
        for prim in mesh["primitives"]:
            key = json.dumps([prim["attributes"], prim.get("targets", [])], sort_keys=True)
            if key in seen:
                continue
            seen.add(key)
            n_v += doc["accessors"][prim["attributes"]["POSITION"]]["count"]
            tn = prim.get("extras", {}).get("targetNames") or mesh.get("extras", {}).get("targetNames") or []
            for t in range(len(prim.get("targets", []))):
                name = tn[t] if t < len(tn) else f"{mesh.get('name', 'mesh' + str(node['mesh']))}.{t}"
                if name not in names:
                    names.append(name)
    ext = doc.get("extensions", {})
    expressions, head, neck = {}, None, None
    if "VRM" in ext:
        for g in ext["VRM"]["blendShapeMaster"]["blendShapeGroups"]:
            preset = {p.lower(): p for p in VRM0_PRESETS}.get(g["presetName"].lower(), "")
            expressions[preset or g["name"]] = len({(b["mesh"], b["index"]) for b in g["binds"]})
        bones = {b["bone"]: b["node"] for b in ext["VRM"]["humanoid"]["humanBones"]}
    elif "VRMC_vrm" in ext:
        back = {v: k for k, v in VRM1_FROM_VRM0.items()}
        for group in ("preset", "custom"):
            for key, e in ext["VRMC_vrm"]["expressions"].get(group, {}).items():
                name = back.get(key, key) if group == "preset" else key
                expressions[name] = len({(b["node"], b["index"]) for b in e.get("morphTargetBinds", [])})
        bones = {b: v["node"] for b, v in ext["VRMC_vrm"]["humanoid"]["humanBones"].items()}
    else:
        bones = {}
    head, neck = bones.get("head"), bones.get("neck")
    textures = {m["pbrMetallicRoughness"]["baseColorTexture"]["index"] for m in doc.get("materials", [])
                if "baseColorTexture" in m.get("pbrMetallicRoughness", {})}
    return {"n_vertices": n_v, "names": names, "expressions": expressions, "head": head, "neck": neck,
            "textures": len(textures)}


@pytest.mark.parametrize("name", KIT)
def test_every_kit_file_imports_with_the_counts_its_json_gives(name):
    path = kit(name)
    doc, _ = read_doc(path)
    want = expected_counts(doc)
    c = read_gltf(path)
    assert c.n_vertices == want["n_vertices"]
    assert list(c.shape_names) == want["names"]
    if want["expressions"]:
        e = c.expressions
        assert list(e.names) == list(want["expressions"])
        assert [len(e.binds(i)[0]) for i in range(e.n_expressions)] == list(want["expressions"].values())
    for bone in ("head", "neck"):
        if want[bone] is not None:
            stored = c.skeleton.bones[bone]
            assert c.source["node_from_file"][stored] == want[bone]
    assert len(c.look.texture_names) == want["textures"]


def test_godette_names_textures_binds_and_meta():
    c = read_gltf(kit("Godette_vrm_v4.vrm"))
    assert c.n_shapes == 15 and c.shape_names[3:5] == ("blink_left", "blink_right")
    s, w = c.expressions.binds(c.expressions.names.index("Blink"))
    assert sorted(s.tolist()) == [3, 4] and w.tolist() == [1.0, 1.0]  # VRM 0.x weight 100 -> 1
    assert c.source["meta"]["title"] == "Low-Poly Godette" and c.source["meta"]["author"] == "SirRichard94"
    assert "SirRichard94" in c.credits and "Lyuma" in c.credits and "CC BY" in c.credits
    assert c.look.shading[c.material_names.index("Face"), 0] == 2  # MToon -> toon


def test_simple_morph_at_its_default_weights_gives_the_spec_arithmetic():
    path = kit("SimpleMorph.gltf")
    doc, buffers = read_doc(path)
    prim = doc["meshes"][0]["primitives"][0]
    base = raw_accessor(doc, buffers, prim["attributes"]["POSITION"])
    t0, t1 = (raw_accessor(doc, buffers, t["POSITION"]) for t in prim["targets"])
    w = doc["meshes"][0]["weights"]
    want = base + w[0] * t0 + w[1] * t1  # glTF 2.0 §3.7.2.2: base + Σ weight_i * target_i
    c = read_gltf(path)
    d = c.dense_deltas()
    weights = [c.source["default_weights"][n] for n in c.shape_names]
    assert weights == [0.5, 0.5]
    np.testing.assert_allclose(c.vertices + weights[0] * d[0] + weights[1] * d[1], want, atol=1e-6)


def trs(node) -> np.ndarray:
    x, y, z, qw = node.get("rotation", [0, 0, 0, 1])
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * qw), 2 * (x * z + y * qw)],
                  [2 * (x * y + z * qw), 1 - 2 * (x * x + z * z), 2 * (y * z - x * qw)],
                  [2 * (x * z - y * qw), 2 * (y * z + x * qw), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r @ np.diag(node.get("scale", [1, 1, 1]))
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


@pytest.mark.parametrize("name", ["pose_rotation_scale_shape_key_skinned.vrm", "Godette_vrm_v4.vrm",
                                  "subdivision_shapekey_modifier_vrm1.vrm"])
def test_skinned_files_have_their_node_transforms_and_skin_applied(name):
    """Stored vertices = the spec's skinning at the rest pose, sum_k w_k G(joint_k) IBM_k v, computed here
    (turned 180 degrees about +Y for VRM 0.x); stored node world transforms = the file's TRS chain."""
    path = kit(name)
    doc, buffers = read_doc(path)
    parent = {c: i for i, n in enumerate(doc["nodes"]) for c in n.get("children", [])}
    cache = {}

    def world(i):
        if i not in cache:
            cache[i] = trs(doc["nodes"][i]) if i not in parent else world(parent[i]) @ trs(doc["nodes"][i])
        return cache[i]

    turn = np.diag([-1.0, 1, -1, 1]) if "VRM" in doc.get("extensions", {}) else np.eye(4)
    want = []
    for i in scene_nodes(doc):
        node = doc["nodes"][i]
        if "mesh" not in node:
            continue
        skin = doc["skins"][node["skin"]]
        ibm = raw_accessor(doc, buffers, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
        joint_m = np.array([world(j) for j in skin["joints"]]) @ ibm
        seen = set()
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim["attributes"]["POSITION"] in seen:
                continue
            seen.add(prim["attributes"]["POSITION"])
            pos = raw_accessor(doc, buffers, prim["attributes"]["POSITION"])
            joints = raw_accessor(doc, buffers, prim["attributes"]["JOINTS_0"]).astype(int)
            weights = raw_accessor(doc, buffers, prim["attributes"]["WEIGHTS_0"])
            weights /= weights.sum(axis=1, keepdims=True)
            for v in range(len(pos)):
                m = sum(weights[v, k] * joint_m[joints[v, k]] for k in range(4))
                want.append((turn @ m @ np.r_[pos[v], 1])[:3])
    c = read_gltf(path)
    np.testing.assert_allclose(c.vertices, want, atol=1e-5)
    g = c.skeleton.global_transforms()
    for stored, file_node in enumerate(c.source["node_from_file"]):
        np.testing.assert_allclose(g[stored], turn @ world(file_node), atol=1e-5)


def test_godette_faces_plus_z_in_metres_head_above_neck_above_hips():
    c = read_gltf(kit("Godette_vrm_v4.vrm"))
    assert c.units == "m" and c.source["turned_y180"]
    k = c.skeleton
    g = k.global_transforms()
    y = {b: g[k.bones[b]][1, 3] for b in ("head", "neck", "hips")}
    assert y["head"] > y["neck"] > y["hips"] > 0
    height = c.vertices[:, 1].max() - c.vertices[:, 1].min()
    assert 0.5 < height < 2.5
    # facing +Z: the eyes (the vertices the blinks move) and the mouth ("ah") lie in front of the head
    # bone, the back of the head behind it; and the character's left is +X, as for the ICT head
    head = g[k.bones["head"]][:3, 3]
    moved = {n: c.vertices[c.delta_indices[c.shape_slice(c.shape_names.index(n))]] for n in
             ("blink_left", "blink_right", "ah")}
    for n, v in moved.items():
        assert v[:, 2].min() > head[2] + 0.05, n
    face = c.layout.primitives[c.layout.mesh_names.index("FaceMesh")]
    fv = c.vertices[face[0]:face[0] + face[1]]
    assert fv[fv[:, 1] > y["neck"], 2].min() < head[2] - 0.05
    assert moved["blink_left"][:, 0].mean() > 0.03 > -0.03 > moved["blink_right"][:, 0].mean()
