"""The plan of the meshes read: which primitives share their vertices, and what the scene will store, from the JSON.

Before any accessor is decoded, each mesh of the default scene is planned
once, however many nodes instance it: its primitives are checked (objects,
triangle lists, attributes and targets naming accessors) and grouped by their
attributes and targets, since primitives with the same ones share one vertex
list (Godette's body has three materials over one); its default morph weights
are read. Then every instance is counted against the scene's limits
(:class:`~.structure_limits.SceneSize`): its primitives, the vertices of each
group stored once more, the triangles. Grouping by a key computed once per
primitive keeps this linear in the number of primitives, however many groups
there are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from facepuppet.offline.io.gltf.read_state import ReadState, target_names
from facepuppet.offline.io.gltf.structure_limits import SceneSize
from facepuppet.offline.io.gltf_container import GltfFile

MODES = {0: "points", 1: "lines", 2: "line loop", 3: "line strip", 4: "triangles", 5: "triangle strip",
         6: "triangle fan"}

Key = tuple  # (sorted attribute (name, (type, accessor)) pairs, per target its sorted pairs)


@dataclass
class MeshPlan:
    """One mesh of the file as the reader will read it.

    ``keys[p]`` is primitive p's attributes and targets; ``members[key]`` the primitives sharing them, in
    file order (their vertices are stored once per instance, the first of them read for all);
    ``default_weights`` its ``weights`` by morph target name (non-zero ones).
    """

    index: int
    mesh: dict
    primitives: list
    keys: list[Key] = field(default_factory=list)
    members: dict[Key, list[int]] = field(default_factory=dict)
    default_weights: dict[str, float] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The mesh's name, else ``mesh<index>``."""
        name = self.mesh.get("name")
        return name if isinstance(name, str) and name else f"mesh{self.index}"


def plan_meshes(state: ReadState, instances: list[tuple[int, int]]) -> list[MeshPlan]:
    """The plan of each instance ``(stored node, file node)``'s mesh (one plan per mesh, shared by its
    instances), every instance counted against the scene's limits; refused by name before any decoding."""
    f = state.f
    size = SceneSize(f)
    plans: dict[int, MeshPlan] = {}
    out = []
    for _, i in instances:
        m = f.get(state.doc["nodes"][i], "mesh", int, f"nodes[{i}]")
        mesh = f.obj("meshes", m, f"nodes[{i}].mesh")
        repeat = m in plans
        if not repeat:
            plans[m] = _plan(f, m, mesh)
        plan = plans[m]
        size.add_instance(i, m, len(plan.primitives))
        stored = 0
        for members in plan.members.values():
            first = plan.primitives[members[0]]
            n = size.add_vertices(f"meshes[{m}].primitives[{members[0]}]", first["attributes"],
                                  len(first.get("targets", [])))
            stored += n
            for p in members:
                size.add_triangles(f"meshes[{m}].primitives[{p}]", plan.primitives[p], n)
        if repeat:
            size.add_repeat(i, m, stored)
        out.append(plan)
    return out


def _plan(f: GltfFile, m: int, mesh: dict) -> MeshPlan:
    mw = f"meshes[{m}]"
    prims = f.get(mesh, "primitives", list, mw)
    if not prims:
        f.fail(f"{mw}.primitives", "a mesh needs at least one primitive")
    plan = MeshPlan(m, mesh, prims)
    for p, prim in enumerate(prims):
        key = _key(f, prim, f"{mw}.primitives[{p}]", p)
        plan.keys.append(key)
        plan.members.setdefault(key, []).append(p)
    plan.default_weights = _default_weights(f, plan)
    return plan


def _key(f: GltfFile, prim: object, pw: str, p: int) -> Key:
    """Primitive ``p`` (``prim``)'s attributes and targets as a key: equal keys, equal JSON."""
    if not isinstance(prim, dict):
        f.fail(pw, "expected an object")
    mode = f.get(prim, "mode", int, pw, 4)
    if mode != 4:
        f.fail(f"{pw}.mode", f"{mode} ({MODES.get(mode, 'unknown')}): only triangle lists (4) are read")
    attrs = f.get(prim, "attributes", dict, pw)
    targets = f.get(prim, "targets", list, pw, [])
    for t, target in enumerate(targets):
        if not isinstance(target, dict):
            f.fail(f"{pw}.targets[{t}]", "expected an object")
    return _pairs(attrs, p), tuple(_pairs(target, p) for target in targets)


def _pairs(o: dict, p: int) -> tuple:
    """The (name, value) pairs of an attributes or target object, sorted. A value is an accessor index; one
    that is not keeps its JSON type apart (1, 1.0 and true differ), and an array or object value makes the key
    primitive ``p``'s own (such a primitive shares no vertices; it is refused where that accessor is read)."""
    return tuple(sorted((name, (type(v).__name__, v) if v is None or isinstance(v, (int, float, str))
                         else ("own", p)) for name, v in o.items()))


def _default_weights(f: GltfFile, plan: MeshPlan) -> dict[str, float]:
    """The mesh's non-zero default ``weights`` by target name (the names of ``extras.targetNames`` of the mesh,
    else of its first primitive, else ``<mesh name>.<index>``); a weight must be a finite number."""
    weights = plan.mesh.get("weights")
    out: dict[str, float] = {}
    if not (isinstance(weights, list) and weights):
        return out
    names = target_names(plan.mesh.get("extras")) or target_names(plan.primitives[0].get("extras"))
    for t, wt in enumerate(weights):
        if not isinstance(wt, (int, float)) or isinstance(wt, bool) or not wt:
            continue
        value = float(wt) if isinstance(wt, float) or abs(wt) < 2 ** 1023 else math.inf
        if not math.isfinite(value):
            f.fail(f"meshes[{plan.index}].weights[{t}]", f"{value}: a default morph weight must be a finite number")
        name = names[t] if t < len(names) and isinstance(names[t], str) and names[t] else f"{plan.name}.{t}"
        out[name] = value
    return out
