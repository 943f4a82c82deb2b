"""The VRM part of ``check-gltf``: references of VRM 0.x (``extensions.VRM``) and VRM 1.0 (``VRMC_vrm``).

What an application loading the avatar follows: humanoid bones, the first-person
bone and mesh annotations, expression binds (to meshes and morph targets that
exist, with weights in the version's range: 0..100 in VRM 0.x, 0..1 in 1.0),
spring bone groups and their colliders, and the texture indices of VRM 0.x
material properties. Every value is read through :class:`.JsonWalk`'s typed
getters, so a wrong type is a problem naming its JSON path, never an exception.
"""

from __future__ import annotations

from typing import Any

from facepuppet.offline.io.gltf_check_walk import JsonWalk, is_int, is_number, join, show

__all__ = ["check_vrm0", "check_vrm1"]


def check_vrm0(c: JsonWalk, n_targets: dict[int, int]) -> None:
    """VRM 0.x references; ``n_targets``: the morph target count of each mesh."""
    ext = c.value(c.dict_at(c.doc, "extensions", ""), "VRM", dict, "extensions")
    if ext is None:
        return
    w = "extensions.VRM"
    humanoid = c.dict_at(ext, "humanoid", w)
    for _, bone, bw in c.entries(c.list_at(humanoid, "humanBones", f"{w}.humanoid"), f"{w}.humanoid.humanBones"):
        c.node_ref(bone.get("node"), f"{bw}.node")
    fw = f"{w}.firstPerson"
    fp = c.dict_at(ext, "firstPerson", w)
    if "firstPersonBone" in fp:
        c.node_ref(fp["firstPersonBone"], f"{fw}.firstPersonBone", allow_minus_one=True)
    n_meshes = len(c.items("meshes"))
    for k, a in enumerate(c.list_at(fp, "meshAnnotations", fw)):
        m = a.get("mesh") if isinstance(a, dict) else None
        if not is_int(m) or not 0 <= m < n_meshes:
            c.bad(f"{fw}.meshAnnotations[{k}].mesh", f"{show(m)} is not a mesh index")
    gw = f"{w}.blendShapeMaster.blendShapeGroups"
    groups = c.list_at(c.dict_at(ext, "blendShapeMaster", w), "blendShapeGroups", f"{w}.blendShapeMaster")
    for _, group, g_w in c.entries(groups, gw):
        for _, bind, bw in c.entries(c.list_at(group, "binds", g_w), f"{g_w}.binds"):
            m, i = bind.get("mesh"), bind.get("index")
            if not is_int(m) or not 0 <= m < n_meshes:
                c.bad(f"{bw}.mesh", f"{show(m)} is not a mesh index")
            else:
                _bind_target(c, bw, m, i, n_targets)
            _bind_weight(c, bw, bind.get("weight", 100), 100, "0.x")
    _spring_bones(c, c.dict_at(ext, "secondaryAnimation", w), f"{w}.secondaryAnimation")
    n_tex = len(c.items("textures"))
    for _, prop, pw in c.entries(c.list_at(ext, "materialProperties", w), f"{w}.materialProperties"):
        for name, t in c.dict_at(prop, "textureProperties", pw).items():
            if not is_int(t) or not 0 <= t < n_tex:
                c.bad(join(f"{pw}.textureProperties", name), f"{show(t)} is not a texture index")


def _spring_bones(c: JsonWalk, sec: dict, sw: str) -> None:
    """VRM 0.x ``secondaryAnimation``: bone groups' bones, centres and collider groups; colliders' nodes."""
    colliders = c.list_at(sec, "colliderGroups", sw)
    for _, group, gw in c.entries(c.list_at(sec, "boneGroups", sw), f"{sw}.boneGroups"):
        for k, b in enumerate(c.list_at(group, "bones", gw)):
            c.node_ref(b, f"{gw}.bones[{k}]")
        if "center" in group:
            c.node_ref(group["center"], f"{gw}.center", allow_minus_one=True)
        for k, ci in enumerate(c.list_at(group, "colliderGroups", gw)):
            if not is_int(ci) or not 0 <= ci < len(colliders):
                c.bad(f"{gw}.colliderGroups[{k}]", f"{show(ci)} is not a collider group index ({len(colliders)})")
    for _, group, gw in c.entries(colliders, f"{sw}.colliderGroups"):
        c.node_ref(group.get("node"), f"{gw}.node")


def check_vrm1(c: JsonWalk, n_targets: dict[int, int]) -> None:
    """VRM 1.0 references; ``n_targets``: the morph target count of each mesh."""
    ext = c.value(c.dict_at(c.doc, "extensions", ""), "VRMC_vrm", dict, "extensions")
    if ext is None:
        return
    w = "extensions.VRMC_vrm"
    for key in ("specVersion", "meta", "humanoid"):
        if key not in ext:
            c.bad(f"{w}.{key}", "missing (required)")
    meta = c.dict_at(ext, "meta", w)
    if isinstance(ext.get("meta", {}), dict):
        for key in ("name", "authors", "licenseUrl"):
            if key not in meta:
                c.bad(f"{w}.meta.{key}", "missing (required)")
    bones = c.dict_at(c.dict_at(ext, "humanoid", w), "humanBones", f"{w}.humanoid")
    for b, v in bones.items():
        c.node_ref(v.get("node") if isinstance(v, dict) else None, f"{join(f'{w}.humanoid.humanBones', b)}.node")
    fw = f"{w}.firstPerson"
    for k, a in enumerate(c.list_at(c.dict_at(ext, "firstPerson", w), "meshAnnotations", fw)):
        c.node_ref(a.get("node") if isinstance(a, dict) else None, f"{fw}.meshAnnotations[{k}].node")
    nodes = c.items("nodes")
    expressions = c.dict_at(ext, "expressions", w)
    for group in ("preset", "custom"):
        for name, e in c.dict_at(expressions, group, f"{w}.expressions").items():
            ew = join(f"{w}.expressions.{group}", name)
            if not isinstance(e, dict):
                c.bad(ew, f"{show(e)}: must be an object")
                continue
            for _, bind, bw in c.entries(c.list_at(e, "morphTargetBinds", ew), f"{ew}.morphTargetBinds"):
                node, i = bind.get("node"), bind.get("index")
                if not is_int(node) or not 0 <= node < len(nodes):
                    c.bad(f"{bw}.node", f"{show(node)} is not a node index")
                    continue
                m = nodes[node].get("mesh") if isinstance(nodes[node], dict) else None
                if not is_int(m):
                    c.bad(f"{bw}.node", f"node {node} has no mesh")
                else:
                    _bind_target(c, bw, m, i, n_targets)
                _bind_weight(c, bw, bind.get("weight", 1.0), 1, "1.0")


def _bind_target(c: JsonWalk, bw: str, m: int, i: Any, n_targets: dict[int, int]) -> None:
    """An expression bind's morph target index ``i`` of mesh ``m``, within the mesh's targets."""
    if not is_int(i) or not 0 <= i < n_targets.get(m, 0):
        c.bad(f"{bw}.index", f"{show(i)}: mesh {m} has {n_targets.get(m, 0)} morph targets")


def _bind_weight(c: JsonWalk, bw: str, weight: Any, full: float, version: str) -> None:
    """An expression bind's weight, a number in 0..``full`` (100 in VRM 0.x, 1 in 1.0)."""
    if not is_number(weight) or not 0 <= weight <= full:
        c.bad(f"{bw}.weight", f"{show(weight)}; VRM {version} bind weights are 0..{full:g}")
