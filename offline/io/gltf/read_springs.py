"""Spring bones of a VRM read into the character: VRM 0.x ``secondaryAnimation`` and VRM 1.0 ``VRMC_springBone``.

Both versions become one form, ``settings["springs"]`` of the character table
(:mod:`facepuppet.runtime.model.springs` reads and checks it at run time):
chains of joints, each joint a node that turns so that its tail follows the
simulation, and colliders (spheres and capsules on nodes). Node indices are
the character's stored nodes; vectors are in the stored frame.

* **VRM 1.0** (``VRMC_springBone-1.0``, "springs"): each spring's joints in
  order; joint k turns toward joint k + 1 with joint k's settings, the last
  joint is only a tail. Defaults are the schema's: stiffness 1, dragForce 0.5,
  gravityPower 0, gravityDir (0, -1, 0), hitRadius 0.
* **VRM 0.x** (``secondaryAnimation``): each bone group's ``bones`` are roots;
  every node under a root is a joint whose tail is its first child, or, on a
  leaf, a virtual tail 7 cm along the leaf's own offset from its parent (what
  UniVRM and three-vrm do). The group's settings (``stiffiness``, UniVRM's
  spelling, or ``stiffness``; ``dragForce``, ``gravityPower``, ``gravityDir``,
  ``hitRadius``, ``center``) apply to all of them; defaults are three-vrm's
  (stiffness 1, drag 0.4). Collider offsets are written in Unity's axes, so
  their z is negated (three-vrm: "z is opposite in VRM0.0"); ``gravityDir`` is
  a world direction and turns with the avatar (the stored frame is turned 180°
  about +Y).

Sizes are bounded (:data:`MAX_JOINTS`, :data:`MAX_COLLIDERS`, :data:`MAX_CHAINS`)
before anything is built; a field of the wrong type, a non-finite number, a
negative radius or a drag outside [0, 1] is refused naming the JSON path. A
node outside the default scene is dropped with a warning, as a node simulated
by two groups is (the first keeps it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.read_state import ReadState, extensions_of

#: At most this many joints, colliders and chains in one avatar (VRoid avatars have a few hundred joints).
MAX_JOINTS = 4096
MAX_COLLIDERS = 1024
MAX_CHAINS = 1024
#: The virtual tail of a VRM 0.x leaf bone, metres.
VIRTUAL_TAIL = 0.07
_NUMBER = (int, float)


def read_springs(state: ReadState) -> None:
    """``state.springs``: the chains and colliders of the file ({} when it has none)."""
    ext = extensions_of(state.doc).get("VRMC_springBone")
    if ext is not None:
        state.springs = _read1(state, ext)
    elif state.vrm0 is not None and state.vrm0.get("secondaryAnimation") is not None:
        state.springs = _read0(state, state.vrm0["secondaryAnimation"])


# -- checked JSON values ----------------------------------------------------------------------------------
def _obj(state: ReadState, value: Any, where: str) -> dict:
    if not isinstance(value, dict):
        state.f.fail(where, f"expected an object, found {type(value).__name__}")
    return value


def _list(state: ReadState, value: Any, where: str, limit: int) -> list:
    if not isinstance(value, list):
        state.f.fail(where, f"expected an array, found {type(value).__name__}")
    if len(value) > limit:
        state.f.fail(where, f"{len(value)} entries; at most {limit} are read")
    return value


def _number(state: ReadState, o: dict, key: str, where: str, default: float, lo: float = -np.inf,
            hi: float = np.inf) -> float:
    value = o.get(key, default)
    if not isinstance(value, _NUMBER) or isinstance(value, bool) or not np.isfinite(value):
        state.f.fail(f"{where}.{key}", f"expected a finite number, found {value!r}")
    if not lo <= value <= hi:
        state.f.fail(f"{where}.{key}", f"{value!r} is outside [{lo}, {hi}]")
    return float(value)


def _vector(state: ReadState, o: dict, key: str, where: str, default: tuple, xyz: bool = False) -> list[float]:
    """A 3-vector: an array of 3 finite numbers (VRM 1.0) or an object {x, y, z} (VRM 0.x, ``xyz``)."""
    value = o.get(key)
    if value is None:
        return [float(x) for x in default]
    if xyz:
        v = _obj(state, value, f"{where}.{key}")
        return [_number(state, v, axis, f"{where}.{key}", 0.0) for axis in "xyz"]
    if not (isinstance(value, list) and len(value) == 3):
        state.f.fail(f"{where}.{key}", f"expected an array of 3 numbers, found {value!r}")
    return [_number(state, {"v": x}, "v", f"{where}.{key}[{i}]", 0.0) for i, x in enumerate(value)]


def _node(state: ReadState, value: Any, where: str) -> int | None:
    """The stored node of a file node index; None (warned) when the node is not in the default scene."""
    state.f.obj("nodes", value, where)
    if value not in state.stored_of:
        state.warn(f"{where}: node {value} is not in the default scene (dropped)")
        return None
    return int(state.stored_of[value])


def _index(state: ReadState, value: Any, n: int, where: str, what: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < n:
        state.f.fail(where, f"{value!r} is not an index into {what} (0..{n - 1})")
    return value


# -- the stored skeleton ----------------------------------------------------------------------------------
def _children(state: ReadState) -> list[list[int]]:
    """Stored children of each stored node, in the file's order (the stored order is depth first by it)."""
    out: list[list[int]] = [[] for _ in range(len(state.parent))]
    for s, p in enumerate(state.parent):
        if p >= 0:
            out[int(p)].append(s)
    return out


def _local_point(state: ReadState, node: int, tail_node: int, where: str) -> list[float]:
    """The rest position of ``tail_node`` in the frame of ``node``."""
    if not abs(np.linalg.det(state.world[node][:3, :3])) > 1e-12:
        state.f.fail(where, f"node {node} has a singular transform (a zero scale): a joint needs a frame")
    p = np.linalg.solve(state.world[node], state.world[tail_node][:, 3])
    return [float(x) for x in p[:3]]


def _is_below(state: ReadState, node: int, ancestor: int) -> bool:
    while node >= 0:
        node = int(state.parent[node])
        if node == ancestor:
            return True
    return False


def _joint(node: int, tail_node: int, tail: list[float], settings: dict) -> dict:
    return {"node": node, "tail_node": tail_node, "tail": tail, **settings}


# -- VRM 1.0 ------------------------------------------------------------------------------------------------
def _read1(state: ReadState, ext: Any) -> dict:
    w = "extensions.VRMC_springBone"
    ext = _obj(state, ext, w)
    colliders, stored_collider = [], {}
    for k, c in enumerate(_list(state, ext.get("colliders", []), f"{w}.colliders", MAX_COLLIDERS)):
        where = f"{w}.colliders[{k}]"
        c = _obj(state, c, where)
        node = _node(state, c.get("node"), f"{where}.node")
        shape = _obj(state, c.get("shape"), f"{where}.shape")
        if "sphere" in shape:
            s, sw = _obj(state, shape["sphere"], f"{where}.shape.sphere"), f"{where}.shape.sphere"
            entry = {"shape": "sphere", "offset": _vector(state, s, "offset", sw, (0, 0, 0)),
                     "tail": [0.0, 0.0, 0.0], "radius": _number(state, s, "radius", sw, 0.0, 0.0)}
        elif "capsule" in shape:
            s, sw = _obj(state, shape["capsule"], f"{where}.shape.capsule"), f"{where}.shape.capsule"
            entry = {"shape": "capsule", "offset": _vector(state, s, "offset", sw, (0, 0, 0)),
                     "tail": _vector(state, s, "tail", sw, (0, 0, 0)),
                     "radius": _number(state, s, "radius", sw, 0.0, 0.0)}
        else:
            state.f.fail(f"{where}.shape", "expected a sphere or a capsule")
        if node is not None:
            stored_collider[k] = len(colliders)
            colliders.append({"node": node, **entry})
    groups = []
    for k, g in enumerate(_list(state, ext.get("colliderGroups", []), f"{w}.colliderGroups", MAX_COLLIDERS)):
        where = f"{w}.colliderGroups[{k}]"
        g = _obj(state, g, where)
        refs = _list(state, g.get("colliders", []), f"{where}.colliders", MAX_COLLIDERS)
        n_c = len(ext.get("colliders", []))
        idx = [_index(state, c, n_c, f"{where}.colliders[{i}]", f"{w}.colliders") for i, c in enumerate(refs)]
        groups.append([stored_collider[i] for i in idx if i in stored_collider])
    chains, taken, n_joints = [], set(), 0
    for k, spring in enumerate(_list(state, ext.get("springs", []), f"{w}.springs", MAX_CHAINS)):
        where = f"{w}.springs[{k}]"
        spring = _obj(state, spring, where)
        joints_json = _list(state, spring.get("joints", []), f"{where}.joints", MAX_JOINTS)
        n_joints += len(joints_json)
        if n_joints > MAX_JOINTS:
            state.f.fail(f"{where}.joints", f"more than {MAX_JOINTS} joints in the springs")
        nodes, settings = [], []
        for i, j in enumerate(joints_json):
            jw = f"{where}.joints[{i}]"
            j = _obj(state, j, jw)
            nodes.append(_node(state, j.get("node"), f"{jw}.node"))
            settings.append({"stiffness": _number(state, j, "stiffness", jw, 1.0, 0.0),
                             "drag": _number(state, j, "dragForce", jw, 0.5, 0.0, 1.0),
                             "gravity_power": _number(state, j, "gravityPower", jw, 0.0, 0.0),
                             "gravity_dir": _vector(state, j, "gravityDir", jw, (0, -1, 0)),
                             "hit_radius": _number(state, j, "hitRadius", jw, 0.0, 0.0)})
        joints = []
        for i in range(len(nodes) - 1):
            node, tail = nodes[i], nodes[i + 1]
            if node is None or tail is None:
                break  # the rest of the chain hangs from a dropped node
            if not _is_below(state, tail, node):
                state.f.fail(f"{where}.joints[{i + 1}].node", f"node {tail} is not below joints[{i}]'s node "
                                                              "(a spring's joints go from parent to child)")
            if node in taken:
                state.warn(f"{where}.joints[{i}]: node {node} is already simulated by another spring (dropped)")
                continue
            taken.add(node)
            joints.append(_joint(node, tail, _local_point(state, node, tail, f"{where}.joints[{i}].node"),
                                 settings[i]))
        group_refs = _list(state, spring.get("colliderGroups", []), f"{where}.colliderGroups", MAX_COLLIDERS)
        cols = [c for i, g in enumerate(group_refs)
                for c in groups[_index(state, g, len(groups), f"{where}.colliderGroups[{i}]",
                                       f"{w}.colliderGroups")]]
        center = -1
        if spring.get("center") is not None:
            c = _node(state, spring["center"], f"{where}.center")
            center = -1 if c is None else c
        name = spring.get("name") if isinstance(spring.get("name"), str) else f"spring{k}"
        if joints:
            chains.append({"name": name, "center": center, "colliders": list(dict.fromkeys(cols)),
                           "joints": joints})
    return {"chains": chains, "colliders": colliders}


# -- VRM 0.x ------------------------------------------------------------------------------------------------
def _read0(state: ReadState, sa: Any) -> dict:
    w = "extensions.VRM.secondaryAnimation"
    sa = _obj(state, sa, w)
    colliders, group_colliders = [], []
    for k, g in enumerate(_list(state, sa.get("colliderGroups", []), f"{w}.colliderGroups", MAX_COLLIDERS)):
        where = f"{w}.colliderGroups[{k}]"
        g = _obj(state, g, where)
        node = _node(state, g.get("node"), f"{where}.node")
        mine = []
        for i, c in enumerate(_list(state, g.get("colliders", []), f"{where}.colliders", MAX_COLLIDERS)):
            cw = f"{where}.colliders[{i}]"
            c = _obj(state, c, cw)
            x, y, z = _vector(state, c, "offset", cw, (0, 0, 0), xyz=True)
            radius = _number(state, c, "radius", cw, 0.0, 0.0)
            if node is not None:
                if len(colliders) >= MAX_COLLIDERS:
                    state.f.fail(cw, f"more than {MAX_COLLIDERS} colliders")
                mine.append(len(colliders))
                colliders.append({"node": node, "shape": "sphere", "offset": [x, y, -z], "tail": [0.0, 0.0, 0.0],
                                  "radius": radius})
        group_colliders.append(mine)
    children = _children(state)
    chains, taken, n_joints = [], set(), 0
    for k, g in enumerate(_list(state, sa.get("boneGroups", []), f"{w}.boneGroups", MAX_CHAINS)):
        where = f"{w}.boneGroups[{k}]"
        g = _obj(state, g, where)
        stiffness_key = "stiffiness" if "stiffiness" in g else "stiffness"
        gx, gy, gz = _vector(state, g, "gravityDir", where, (0, -1, 0), xyz=True)
        settings = {"stiffness": _number(state, g, stiffness_key, where, 1.0, 0.0),
                    "drag": _number(state, g, "dragForce", where, 0.4, 0.0, 1.0),
                    "gravity_power": _number(state, g, "gravityPower", where, 0.0, 0.0),
                    "gravity_dir": [-gx, gy, -gz] if state.turn else [gx, gy, gz],
                    "hit_radius": _number(state, g, "hitRadius", where, 0.0, 0.0)}
        refs = _list(state, g.get("colliderGroups", []), f"{where}.colliderGroups", MAX_COLLIDERS)
        cols = [c for i, r in enumerate(refs)
                for c in group_colliders[_index(state, r, len(group_colliders), f"{where}.colliderGroups[{i}]",
                                                f"{w}.colliderGroups")]]
        center = -1
        c = g.get("center", -1)
        if not (isinstance(c, int) and not isinstance(c, bool) and c < 0):
            stored = _node(state, c, f"{where}.center")
            center = -1 if stored is None else stored
        name = g.get("comment") if isinstance(g.get("comment"), str) and g.get("comment") else f"boneGroup{k}"
        for i, root in enumerate(_list(state, g.get("bones", []), f"{where}.bones", MAX_JOINTS)):
            stored_root = _node(state, root, f"{where}.bones[{i}]")
            if stored_root is None:
                continue
            joints, stack = [], [stored_root]
            while stack:  # depth first, parents before children, the file's order of children
                s = stack.pop()
                stack.extend(reversed(children[s]))
                if s in taken:
                    state.warn(f"{where}.bones[{i}]: node {s} ({state.node_names[s]}) is already simulated "
                               "(dropped here)")
                    continue
                n_joints += 1
                if n_joints > MAX_JOINTS:
                    state.f.fail(f"{where}.bones", f"more than {MAX_JOINTS} joints under the bone groups' roots")
                if children[s]:
                    tail_node, tail = children[s][0], [float(x) for x in state.rest_local[children[s][0]][:3, 3]]
                else:
                    offset = np.asarray(state.rest_local[s][:3, 3], np.float64)
                    if np.linalg.norm(offset) < 1e-9:
                        state.warn(f"{where}.bones[{i}]: leaf node {s} ({state.node_names[s]}) sits on its parent; "
                                   "no direction for its virtual tail (dropped)")
                        continue
                    tail_node, tail = -1, [float(x) for x in offset / np.linalg.norm(offset) * VIRTUAL_TAIL]
                taken.add(s)
                joints.append(_joint(s, tail_node, tail, settings))
            if joints:
                chains.append({"name": f"{name}/{state.node_names[stored_root]}", "center": center,
                               "colliders": list(dict.fromkeys(cols)), "joints": joints})
    return {"chains": chains, "colliders": colliders}
