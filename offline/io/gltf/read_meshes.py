"""The meshes of the default scene: vertices, skins, triangles, morph targets, in the stored frame.

Each mesh is planned first (:mod:`.mesh_plan`: its primitives checked and
grouped, every instance counted against the limits of
:mod:`.structure_limits`), so a refusal of the structure comes before any
accessor is decoded. Then, per mesh instance (a node with a mesh), per group
of primitives sharing the same vertex attributes (Godette's body has three
materials over one vertex list; they are stored once and the Layout ranges of
those primitives coincide):

* skinned (node has ``skin`` and the primitive JOINTS_0/WEIGHTS_0): each
  vertex is moved by ``Σ w_i G(joint_i) IBM_i`` (the spec's skinning at the
  rest pose; the mesh node's own transform is ignored, as the spec says);
* otherwise by the node's world transform ``G(node)``;
* normals by the inverse transpose of that matrix, renormalised; morph
  deltas (vectors) by its linear part; a target's normal delta is the
  difference of the transformed unit normals.

Missing normals are computed (area-weighted) from the transformed triangles;
the normal deltas of a target are then computed likewise. Weights are
clipped at 0 and renormalised; a vertex with no weight follows its first
joint.

Shapes: one per distinct morph-target name (``extras.targetNames`` of the
primitive, else of the mesh, else ``<mesh name>.<index>``); the same name on
two meshes is one shape. Only vertices a target moves (or whose unit normal
it turns by more than the OBJ import's ``NORMAL_TOLERANCE``) are stored,
kept sparse as each target is read (one target of a group is dense at a time).
The mesh's default ``weights`` (finite numbers) are not baked into the
neutral; they are kept in ``source["default_weights"]``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.mesh_plan import plan_meshes
from facepuppet.offline.io.gltf.names import UniqueNames
from facepuppet.offline.io.gltf.read_state import ReadState, target_names
from facepuppet.offline.io.rig_import import NORMAL_TOLERANCE

Progress = Callable[[int, int, str], None]


def read_geometry(state: ReadState, progress: Progress | None) -> None:
    """Fill ``state.geo``: every mesh instance of the default scene in the stored frame (see the module doc)."""
    f = state.f
    instances = [(s, i) for s, i in enumerate(state.node_from_file) if "mesh" in state.doc["nodes"][i]]
    plans = plan_meshes(state, instances)  # checked and counted against the limits before any decoding
    out: dict[str, Any] = {"vertices": [], "normals": [], "uv": [], "colors": [], "nodes": [], "weights": [],
                           "triangles": [], "triangle_material": [], "primitives": [], "mesh_names": [],
                           "targets": [], "default_weights": {}, "material_used": set(),
                           "instance_of_mesh": {}, "n_joints": 0, "file_normals": True}
    n_v = n_t = 0
    joints_used: set[int] = set()
    mesh_names = UniqueNames()
    skins: dict[int, dict] = {}
    for k, ((s, i), plan) in enumerate(zip(instances, plans), start=1):
        node = state.doc["nodes"][i]
        m, mw, prims = plan.index, f"meshes[{plan.index}]", plan.primitives
        unique = mesh_names.take(plan.name)
        mesh_index = len(out["mesh_names"])
        out["mesh_names"].append(unique)
        out["instance_of_mesh"].setdefault(m, []).append((mesh_index, s))
        skin = _skin(state, node, i, skins)
        mesh_names_t = target_names(plan.mesh.get("extras"))
        groups: dict[tuple, tuple[int, int]] = {}  # plan key -> (first vertex, n vertices)
        for p, prim in enumerate(prims):
            pw = f"{mw}.primitives[{p}]"
            key = plan.keys[p]
            if key not in groups:
                siblings = [(f"{mw}.primitives[{q}]", prims[q]) for q in plan.members[key]]
                g = _vertices(state, prim["attributes"], prim.get("targets", []), pw, skin, s, siblings)
                groups[key] = (n_v, len(g["positions"]))
                out["vertices"].append(g["positions"])
                out["normals"].append(g["normals"])
                out["file_normals"] &= g["from_file"]
                out["uv"].append(g["uv"])
                out["colors"].append(g["colors"])
                out["nodes"].append(g["nodes"])
                out["weights"].append(g["weights"])
                joints_used.update(np.unique(g["nodes"][g["weights"] > 0]).tolist() if skin is not None else [])
                names = target_names(prim.get("extras")) or mesh_names_t
                for t, (keep, dp, dn) in enumerate(g["targets"]):
                    tname = names[t] if t < len(names) and isinstance(names[t], str) and names[t] \
                        else f"{plan.name}.{t}"
                    out["targets"].append((tname, keep + n_v, dp, dn))
                n_v += len(g["positions"])
            first, count = groups[key]
            tri = _indices(state, prim, pw, count) + first
            material = prim.get("material", -1)
            if material != -1:
                f.obj("materials", material, f"{pw}.material")
            out["material_used"].add(material)
            out["triangles"].append(tri)
            out["triangle_material"].append(np.full(len(tri), material, dtype=np.int64))
            out["primitives"].append([first, count, n_t, len(tri), mesh_index, material])
            n_t += len(tri)
        out["default_weights"].update(plan.default_weights)
        if progress is not None:
            progress(k, len(instances), unique)
    if n_v == 0:
        f.fail("meshes", "the default scene has no mesh on any node: nothing to draw")
    out["n_joints"] = len(joints_used)
    out["vertices"] = np.concatenate(out["vertices"])
    out["normals"] = np.concatenate(out["normals"])
    out["uv"] = np.concatenate(out["uv"])
    out["colors"] = np.concatenate(out["colors"])
    out["vertex_nodes"] = np.concatenate(out["nodes"])
    out["vertex_weights"] = np.concatenate(out["weights"])
    out["triangles"] = np.concatenate(out["triangles"]) if out["triangles"] else np.zeros((0, 3), np.int64)
    out["triangle_material"] = np.concatenate(out["triangle_material"])
    out["primitives"] = np.asarray(out["primitives"], dtype=np.int64).reshape(-1, 6)
    state.geo = out


def _skin(state: ReadState, node: dict, i: int, done: dict[int, dict]) -> dict | None:
    """Per skin: joint stored indices and the joint matrices G(joint) IBM (stored frame); each skin is read
    once into ``done``, however many nodes it skins."""
    if "skin" not in node:
        return None
    f = state.f
    s = f.get(node, "skin", int, f"nodes[{i}]")
    skin = f.obj("skins", s, f"nodes[{i}].skin")
    if s in done:
        return done[s]
    w = f"skins[{s}]"
    joints = f.get(skin, "joints", list, w)
    if not joints:
        f.fail(f"{w}.joints", "a skin needs at least one joint")
    stored = []
    for k, j in enumerate(joints):
        f.obj("nodes", j, f"{w}.joints[{k}]")
        if j not in state.stored_of:
            f.fail(f"{w}.joints[{k}]", f"node {j} is not in the default scene")
        stored.append(state.stored_of[j])
    stored = np.asarray(stored, dtype=np.int64)
    if "inverseBindMatrices" in skin:
        ibm = f.accessor(skin["inverseBindMatrices"], f"{w}.inverseBindMatrices")
        if ibm.shape != (len(joints), 4, 4):
            f.fail(f"{w}.inverseBindMatrices", f"expected {len(joints)} MAT4, found shape {ibm.shape}")
        if not np.isfinite(ibm).all():
            f.fail(f"{w}.inverseBindMatrices", "contains NaN or infinite values")
    else:
        ibm = np.tile(np.eye(4), (len(joints), 1, 1))
    done[s] = {"joints": stored, "matrices": state.world[stored] @ ibm, "where": w}
    return done[s]


def _vertices(state: ReadState, attrs: dict, targets: list, pw: str, skin: dict | None, node: int,
              siblings: list[tuple[str, dict]]) -> dict:
    """The vertices of the primitives ``siblings`` (all sharing these attributes) in the stored frame."""
    f = state.f
    aw = f"{pw}.attributes"
    if "POSITION" not in attrs:
        f.fail(f"{aw}.POSITION", "missing: a primitive needs positions")
    pos = _attr(state, attrs, "POSITION", aw, (3,))
    n = len(pos)
    if not np.isfinite(pos).all():
        bad = int(np.argmax(~np.isfinite(pos).all(axis=1)))
        f.fail(f"{aw}.POSITION", f"vertex {bad} is {pos[bad].tolist()} (NaN or infinite)")
    normals = _attr(state, attrs, "NORMAL", aw, (3,), n) if "NORMAL" in attrs else None
    uv = _attr(state, attrs, "TEXCOORD_0", aw, (2,), n) if "TEXCOORD_0" in attrs else np.zeros((n, 2))
    if "COLOR_0" in attrs:
        c = _attr(state, attrs, "COLOR_0", aw, (3, 4), n)
        colors = np.clip(c[:, :3], 0.0, 1.0)
    else:
        colors = np.ones((n, 3))
    if "JOINTS_1" in attrs or "WEIGHTS_1" in attrs:
        state.warn(f"{aw}: JOINTS_1/WEIGHTS_1 ignored (a character keeps four influences per vertex)")
    if skin is not None and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
        joints = _attr(state, attrs, "JOINTS_0", aw, (4,), n, as_float=False)
        if np.any(joints < 0) or np.any(joints >= len(skin["joints"])):
            bad = int(joints.max())
            f.fail(f"{aw}.JOINTS_0", f"joint {bad} is out of range for the {len(skin['joints'])} joints of "
                                     f"{skin['where']}")
        weights = _attr(state, attrs, "WEIGHTS_0", aw, (4,), n)
        weights = np.clip(np.nan_to_num(weights, nan=0.0, posinf=0.0, neginf=0.0), 0.0, None)
        total = weights.sum(axis=1)
        empty = total <= 0
        if empty.any():
            state.warn(f"{aw}.WEIGHTS_0: {int(empty.sum())} vertices without weight follow their first joint")
            weights[empty] = (1, 0, 0, 0)
            total[empty] = 1.0
        weights = weights / total[:, None]
        weights[weights < 1e-7] = 0.0  # float32 dust; renormalise once more
        weights = weights / weights.sum(axis=1, keepdims=True)
        matrix = np.einsum("vk,vkij->vij", weights, skin["matrices"][joints])
        nodes = skin["joints"][joints]
    else:
        if skin is not None:
            state.warn(f"{pw}: skinned node but no JOINTS_0/WEIGHTS_0: the mesh follows its node")
        matrix = np.broadcast_to(state.world[node], (n, 4, 4))
        nodes = np.zeros((n, 4), dtype=np.int64)
        nodes[:, 0] = node
        weights = np.zeros((n, 4))
        weights[:, 0] = 1.0
    lin = matrix[:, :3, :3]
    world = np.einsum("vij,vj->vi", lin, pos) + matrix[:, :3, 3]
    det = np.linalg.det(lin)
    if np.any(np.abs(det) < 1e-12):
        f.fail(pw, "a vertex's skinning or node transform is singular (zero scale)")
    normal_m = np.linalg.inv(lin).transpose(0, 2, 1)
    # computed normals: over the triangles of every primitive sharing these vertices
    tri = np.concatenate([_indices(state, pr, w, n) for w, pr in siblings]) if normals is None else None
    if normals is not None:
        nrm = _unit(np.einsum("vij,vj->vi", normal_m, normals))
    else:
        nrm = _vertex_normals(world, tri)
    out_targets = []
    for t, target in enumerate(targets):
        tw = f"{pw}.targets[{t}]"
        if not isinstance(target, dict):
            f.fail(tw, "expected an object")
        dp = _attr(state, target, "POSITION", tw, (3,), n) if "POSITION" in target else np.zeros((n, 3))
        if not np.isfinite(dp).all():
            f.fail(f"{tw}.POSITION", "contains NaN or infinite deltas")
        dpw = np.einsum("vij,vj->vi", lin, dp)
        if "NORMAL" in target and normals is not None:
            dn = _attr(state, target, "NORMAL", tw, (3,), n)
            dnw = _unit(np.einsum("vij,vj->vi", normal_m, normals + dn)) - nrm
        elif normals is None:
            dnw = _vertex_normals(world + dpw, tri) - nrm
        else:
            dnw = np.zeros((n, 3))
        dnw[np.linalg.norm(dnw, axis=1) <= NORMAL_TOLERANCE] = 0.0  # as the OBJ import: not stored
        keep = np.flatnonzero(np.any(dpw != 0, axis=1) | np.any(dnw != 0, axis=1))
        out_targets.append((keep, dpw[keep], dnw[keep]))  # sparse at once: one target is dense at a time
    from_file = normals is not None and bool(np.all(np.abs(np.linalg.norm(nrm, axis=1) - 1.0) < 1e-3))
    if normals is not None and not from_file:
        state.warn(f"{aw}.NORMAL: zero or non-finite normals; the character's normals are computed instead")
    return {"positions": world, "normals": nrm, "from_file": from_file, "uv": uv, "colors": colors,
            "nodes": nodes,
            "weights": weights, "targets": out_targets}


def _attr(state: ReadState, attrs: dict, key: str, where: str, widths: tuple, n: int | None = None,
          as_float: bool = True) -> np.ndarray:
    a = state.f.accessor(attrs[key], f"{where}.{key}", as_float=as_float)
    if a.ndim != 2 or a.shape[1] not in widths:
        state.f.fail(f"{where}.{key}", f"accessor {attrs[key]} has {a.shape[1:] or '1'} components per "
                                      f"element, expected {' or '.join(map(str, widths))}")
    if n is not None and len(a) != n:
        state.f.fail(f"{where}.{key}", f"accessor {attrs[key]} has {len(a)} elements but POSITION has {n}")
    return a


def _indices(state: ReadState, prim: dict, pw: str, n: int) -> np.ndarray:
    f = state.f
    if "indices" in prim:
        idx = f.accessor(prim["indices"], f"{pw}.indices", as_float=False)
        if idx.ndim != 1:
            f.fail(f"{pw}.indices", "the index accessor must be SCALAR")
    else:
        idx = np.arange(n, dtype=np.int64)
    if len(idx) % 3:
        f.fail(f"{pw}.indices", f"{len(idx)} indices is not a whole number of triangles")
    if len(idx) and (idx.max() >= n or idx.min() < 0):
        f.fail(f"{pw}.indices", f"index {int(idx.max())} is past the primitive's {n} vertices")
    return idx.reshape(-1, 3)

# -- shapes ------------------------------------------------------------------
def read_shapes(state: ReadState) -> None:
    """Fill ``state.shape_names`` and ``state.deltas``: one shape per distinct target name, sparse (the vertices a
    target moves, or whose normal it turns), over every mesh that has it."""
    geo = state.geo
    order: list[str] = []
    per: dict[str, list] = {}
    for tname, idx, dp, dn in geo["targets"]:
        if tname not in per:
            order.append(tname)
            per[tname] = []
        per[tname].append((idx, dp, dn))
    offsets, idx, pos, nrm = [0], [], [], []
    for tname in order:
        i = np.concatenate([k for k, _, _ in per[tname]])
        o = np.argsort(i, kind="stable")
        idx.append(i[o])
        pos.append(np.concatenate([p for _, p, _ in per[tname]])[o])
        nrm.append(np.concatenate([q for _, _, q in per[tname]])[o])
        offsets.append(offsets[-1] + len(i))
    geo["target_names"] = order
    state.shape_names = tuple(order)
    state.deltas = {
        "delta_offsets": np.asarray(offsets, dtype=np.int64),
        "delta_indices": (np.concatenate(idx) if idx else np.zeros(0)).astype(np.uint32),
        "delta_positions": (np.concatenate(pos) if pos else np.zeros((0, 3))).astype(np.float32),
        "delta_normals": (np.concatenate(nrm) if nrm else np.zeros((0, 3))).astype(np.float32),
    }


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3); a vertex on no triangle gets +Z."""
    face = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                    vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
    n = np.zeros_like(vertices)
    for c in range(3):
        np.add.at(n, triangles[:, c], face)
    length = np.linalg.norm(n, axis=1)
    n[length < 1e-30] = (0.0, 0.0, 1.0)
    return _unit(n)
