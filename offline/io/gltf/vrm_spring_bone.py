"""VRM spring bones: 0.x ``secondaryAnimation`` and 1.0 ``VRMC_springBone``, kept on import, written back, converted.

The reader keeps them raw (0.x inside the kept VRM extension, 1.0's top-level
``VRMC_springBone`` in ``settings.source.kept.spring_bone``); the writers put
them back with their nodes remapped through ``settings.source.node_from_file``
(a collider or joint whose node is not in the character is dropped, with a
warning), in the version being written:

* 0.x → 1.0, as VRM 0.x runtimes (UniVRM, three-vrm) simulate a bone group:
  every node under each root bone is a joint whose tail is its first child,
  so each root gives a spring down the first children, and each other child
  of a branching joint starts a spring of its own; a 0.x leaf swings on a
  virtual tail 7 cm along its own bone (three-vrm: the leaf's offset from its
  parent, normalised), which 1.0 has no word for, so the tail is written as a
  new node (``<leaf>_end``) the spring ends on. The group's settings go on
  each joint (``stiffiness`` becomes ``stiffness``); each 0.x collider group
  (one node, spheres) gives 1.0 sphere colliders and one collider group.
  Offsets are in the collider node's frame, which the 180° turn of the scene
  leaves alone, but 0.x writes them in Unity's left-handed axes (z reversed,
  as three-vrm reads them): (x, y, z) → [x, y, −z]. ``gravityDir`` is a
  world direction in Unity's axes: (x, y, z) → [−x, y, z] in VRM 1.0's glTF
  axes (both face +Z).
* 1.0 → 0.x: each spring is a bone group rooted at its first joint with the
  first joint's settings; each collider is a collider group of its node
  (a capsule as two spheres, at its ends).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.kept_parts import kept
from facepuppet.offline.io.gltf.read_springs import VIRTUAL_TAIL
from facepuppet.offline.io.gltf.write_state import WriteState


def write_spring_bones0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``secondaryAnimation``: the kept one remapped, converted from a VRM 1.0's springs, or empty."""
    src = w.c.source
    if src.get("format") == "vrm1":
        vrm["secondaryAnimation"] = _secondary0_from_1(w, kept(src, "spring_bone", {}), w.node_map())
    else:
        vrm["secondaryAnimation"] = _secondary0(w, raw.get("secondaryAnimation"), w.node_map())
    w.summary.n_springs = len(vrm["secondaryAnimation"]["boneGroups"])


def spring_bone1(w: WriteState, nodes: list[dict]) -> dict | None:
    """VRM 1.0 ``VRMC_springBone`` (the document-level extension): the kept one remapped, converted from a VRM
    0.x's secondary animation (adding its leaves' tail nodes to ``nodes``), or None when there is none."""
    src = w.c.source
    if src.get("format") == "vrm0":
        raw = src.get("vrm_extension") if isinstance(src.get("vrm_extension"), dict) else {}
        sec = raw.get("secondaryAnimation")
        return _spring1_from_0(w, sec, nodes) if isinstance(sec, dict) and sec.get("boneGroups") else None
    spring = kept(src, "spring_bone", {})
    return _spring1(w, spring) if spring else None


def _secondary0(w: WriteState, raw: Any, remap: Callable[[Any], int | None]) -> dict:
    if not isinstance(raw, dict):
        return {"boneGroups": [], "colliderGroups": []}
    colliders, new_index = [], {}
    for k, g in enumerate(raw.get("colliderGroups", []) if isinstance(raw.get("colliderGroups"), list) else []):
        node = remap(g.get("node")) if isinstance(g, dict) else None
        if node is None:
            w.warn(f"secondaryAnimation.colliderGroups[{k}] dropped: its node is not in the character")
            continue
        new_index[k] = len(colliders)
        colliders.append({**g, "node": node})
    groups = []
    for k, g in enumerate(raw.get("boneGroups", []) if isinstance(raw.get("boneGroups"), list) else []):
        if not isinstance(g, dict):
            continue
        bones = [remap(b) for b in _list(g.get("bones")) if remap(b) is not None]
        if not bones:
            w.warn(f"secondaryAnimation.boneGroups[{k}] dropped: none of its bones is in the character")
            continue
        centre = g.get("center", -1)
        g = {**g, "bones": bones, "center": remap(centre) if remap(centre) is not None else -1,
             "colliderGroups": [new_index[i] for i in _list(g.get("colliderGroups")) if i in new_index]}
        groups.append(g)
    return {**raw, "boneGroups": groups, "colliderGroups": colliders}


def _children(w: WriteState) -> list[list[int]]:
    """Each written skeleton node's children in the file's order (a 0.x tail is the first child)."""
    k = w.c.skeleton
    order = w.c.source.get("node_from_file")
    key = (lambda j: order[j]) if isinstance(order, list) and len(order) == k.n_nodes else (lambda j: j)
    children: list[list[int]] = [[] for _ in range(k.n_nodes)]
    for j in range(k.n_nodes):
        if k.parent[j] >= 0:
            children[int(k.parent[j])].append(j)
    return [sorted(c, key=key) for c in children]


def _spring1_from_0(w: WriteState, sec: dict, nodes: list[dict]) -> dict:
    """VRMC_springBone from a VRM 0.x secondaryAnimation (see the module doc)."""
    remap = w.node_map()
    sec = _secondary0(w, sec, remap)  # nodes remapped, the missing ones dropped
    colliders, groups = [], []
    for g in sec["colliderGroups"]:
        members = []
        for c in _list(g.get("colliders")):
            if not isinstance(c, dict):
                continue
            o = c.get("offset") if isinstance(c.get("offset"), dict) else {}
            offset = [_num(o.get("x"), 0.0), _num(o.get("y"), 0.0), 0.0 - _num(o.get("z"), 0.0)]
            members.append(len(colliders))
            colliders.append({"node": g["node"], "shape": {"sphere": {"offset": offset,
                                                                      "radius": _num(c.get("radius"), 0.0)}}})
        groups.append({"name": f"colliderGroup{len(groups)}", "colliders": members})
    children = _children(w)
    k = w.c.skeleton
    tails: dict[int, int] = {}
    springs = []
    for gi, g in enumerate(sec["boneGroups"]):
        gd = g.get("gravityDir") if isinstance(g.get("gravityDir"), dict) else {"x": 0, "y": -1, "z": 0}
        stiffness = g.get("stiffiness", g.get("stiffness"))  # UniVRM's spelling, or the plain one
        settings = {"hitRadius": _num(g.get("hitRadius"), 0.0), "stiffness": _num(stiffness, 1.0),
                    "gravityPower": _num(g.get("gravityPower"), 0.0),
                    "gravityDir": [0.0 - _num(gd.get("x"), 0.0), _num(gd.get("y"), -1.0), _num(gd.get("z"), 0.0)],
                    "dragForce": _num(g.get("dragForce"), 0.4)}
        starts = list(dict.fromkeys(g["bones"]))
        n = 0
        while starts:
            chain = [starts.pop(0)]
            while children[chain[-1]]:
                starts.extend(children[chain[-1]][1:])
                chain.append(children[chain[-1]][0])
            chain.append(_tail_node(w, nodes, chain[-1], k, tails))
            name = g.get("comment") if isinstance(g.get("comment"), str) and g.get("comment") else f"boneGroup{gi}"
            spring: dict[str, Any] = {"name": name if n == 0 else f"{name}.{n}",
                                      "joints": [{"node": j, **settings} for j in chain],
                                      "colliderGroups": [int(c) for c in g.get("colliderGroups", [])]}
            if g.get("center", -1) >= 0:
                spring["center"] = g["center"]
            springs.append(spring)
            n += 1
    w.summary.n_springs = len(springs)
    return {"specVersion": "1.0", "colliders": colliders, "colliderGroups": groups, "springs": springs}


def _tail_node(w: WriteState, nodes: list[dict], leaf: int, k: Any, tails: dict[int, int]) -> int:
    """The new node a 0.x leaf's virtual tail becomes: a child of the leaf, 7 cm along the leaf's own offset
    from its parent (straight up the leaf's frame when it sits on its parent)."""
    if leaf in tails:
        return tails[leaf]
    offset = np.asarray(k.rest_local[leaf][:3, 3], np.float64)
    norm = float(np.linalg.norm(offset))
    direction = offset / norm if norm > 1e-12 else np.array([0.0, 1.0, 0.0])
    nodes.append({"name": f"{k.names[leaf]}_end", "translation": [float(x) for x in direction * VIRTUAL_TAIL]})
    nodes[leaf].setdefault("children", []).append(len(nodes) - 1)
    tails[leaf] = len(nodes) - 1
    return tails[leaf]


def _spring1(w: WriteState, raw: dict) -> dict:
    """A kept VRMC_springBone with its nodes remapped; colliders and joints whose node is gone are dropped."""
    remap = w.node_map()
    out = copy.deepcopy(raw)
    colliders, new_index = [], {}
    for i, c in enumerate(out.get("colliders", []) if isinstance(out.get("colliders"), list) else []):
        node = remap(c.get("node")) if isinstance(c, dict) else None
        if node is None:
            w.warn(f"VRMC_springBone.colliders[{i}] dropped: its node is not in the character")
            continue
        new_index[i] = len(colliders)
        colliders.append({**c, "node": node})
    out["colliders"] = colliders
    groups = out.get("colliderGroups") if isinstance(out.get("colliderGroups"), list) else []
    out["colliderGroups"] = [{**g, "colliders": [new_index[i] for i in _list(g.get("colliders")) if i in new_index]}
                             for g in groups if isinstance(g, dict)]
    springs = []
    for i, s in enumerate(out.get("springs", []) if isinstance(out.get("springs"), list) else []):
        if not isinstance(s, dict):
            continue
        joints = [{**j, "node": remap(j.get("node"))} for j in _list(s.get("joints")) if isinstance(j, dict)
                  and remap(j.get("node")) is not None]
        if len(joints) < 2:
            w.warn(f"VRMC_springBone.springs[{i}] dropped: fewer than two of its joints are in the character")
            continue
        s = {**s, "joints": joints}
        if "center" in s:
            centre = remap(s["center"])
            if centre is None:
                del s["center"]
            else:
                s["center"] = centre
        springs.append(s)
    out["springs"] = springs
    w.summary.n_springs = len(springs)
    return out


def _secondary0_from_1(w: WriteState, raw: dict, remap: Callable[[Any], int | None]) -> dict:
    """VRM 0.x secondaryAnimation from a kept VRMC_springBone (see the module doc)."""
    if not raw:
        return {"boneGroups": [], "colliderGroups": []}
    one = _spring1(w, raw)
    groups0, of_collider = [], {}
    for i, c in enumerate(one["colliders"]):
        shape = c.get("shape") if isinstance(c.get("shape"), dict) else {}
        spheres = []
        if isinstance(shape.get("sphere"), dict):
            spheres = [(shape["sphere"].get("offset"), shape["sphere"].get("radius"))]
        elif isinstance(shape.get("capsule"), dict):
            cap = shape["capsule"]
            spheres = [(cap.get("offset"), cap.get("radius")), (cap.get("tail"), cap.get("radius"))]
        colliders = []
        for offset, radius in spheres:
            o = offset if isinstance(offset, list) and len(offset) == 3 else [0, 0, 0]
            colliders.append({"offset": {"x": _num(o[0], 0.0), "y": _num(o[1], 0.0), "z": 0.0 - _num(o[2], 0.0)},
                              "radius": _num(radius, 0.0)})
        of_collider[i] = len(groups0)
        groups0.append({"node": c["node"], "colliders": colliders})
    bone_groups = []
    for s in one["springs"]:
        j = s["joints"][0]
        gd = j.get("gravityDir") if isinstance(j.get("gravityDir"), list) and len(j["gravityDir"]) == 3 \
            else [0, -1, 0]
        cgs = sorted({of_collider[c] for g in _list(s.get("colliderGroups")) if isinstance(g, int)
                      and 0 <= g < len(one["colliderGroups"]) for c in one["colliderGroups"][g]["colliders"]})
        bone_groups.append({"comment": s.get("name", ""), "stiffiness": _num(j.get("stiffness"), 1.0),
                            "gravityPower": _num(j.get("gravityPower"), 0.0),
                            "gravityDir": {"x": 0.0 - _num(gd[0], 0.0), "y": _num(gd[1], -1.0), "z": _num(gd[2], 0.0)},
                            "dragForce": _num(j.get("dragForce"), 0.5), "center": s.get("center", -1),
                            "hitRadius": _num(j.get("hitRadius"), 0.0), "bones": [j["node"]],
                            "colliderGroups": cgs})
    return {"boneGroups": bone_groups, "colliderGroups": groups0}


def _list(v: Any) -> list:
    return v if isinstance(v, list) else []


def _num(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) else default
