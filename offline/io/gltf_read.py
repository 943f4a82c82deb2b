"""glTF 2.0 / GLB / VRM 0.x / VRM 1.0 -> :class:`~facepuppet.runtime.character.Character` with its parts.

``read_gltf(path)`` reads the default scene (``scene``, else scene 0, else
every root node) and stores, as :mod:`facepuppet.runtime.character_parts`
asks: vertices, normals and morph deltas in the rest pose in world space,
metres, +Y up, facing +Z (a VRM 0.x avatar faces −Z and is turned 180° about
+Y); the node hierarchy renumbered parents first; per vertex four (node,
weight) pairs (a mesh without a skin follows its own node at weight 1);
materials and base colour textures (Pillow); VRM humanoid bones, expressions
and meta.

Geometry, per mesh instance (a node with a mesh), per group of primitives
sharing the same vertex attributes (Godette's body has three materials over
one vertex list; they are stored once and the Layout ranges of those
primitives coincide):

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
it turns by more than the OBJ import's ``NORMAL_TOLERANCE``) are stored.
The mesh's default ``weights`` are not baked into the neutral; they are kept in ``source["default_weights"]``.
"""

from __future__ import annotations

import io
import json
import os
import sys
import warnings as _warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.character import MATERIAL_KINDS, Character
from facepuppet.runtime.character_parts import (
    ALPHA_MODES,
    IDENTITY_UV_TRANSFORM,
    OVERRIDES,
    SHADING,
    Expressions,
    Layout,
    Look,
    Skeleton,
)
from facepuppet.runtime.geometry import quat_to_matrix
from facepuppet.runtime.tables import TablesError, hash_inputs, naming_file
from facepuppet.runtime.vrm_names import VRM0_PRESETS, VRM1_FROM_VRM0

from facepuppet.offline.io.gltf_container import GltfError, GltfFile, read_gltf_file
from facepuppet.offline.io.rig_import import NORMAL_TOLERANCE

__all__ = ["read_gltf", "SUPPORTED_EXTENSIONS", "GltfError"]

#: Extensions whose meaning the reader honours (may be required).
SUPPORTED_EXTENSIONS = frozenset({"KHR_materials_unlit", "KHR_texture_transform", "KHR_mesh_quantization",
                                  "KHR_materials_emissive_strength", "VRM", "VRMC_vrm", "VRMC_materials_mtoon"})
#: Used-only extensions that carry nothing the character needs (no warning): VRM's physics and constraints
#: are kept in the raw VRM JSON for export.
QUIET_EXTENSIONS = frozenset({"VRMC_springBone", "VRMC_node_constraint", "VRMC_vrm_animation"})
TURN_Y180 = np.diag([-1.0, 1.0, -1.0, 1.0])
_VRM0_BY_LOWER = {p.lower(): p for p in VRM0_PRESETS}
_VRM0_FROM_VRM1 = {v: k for k, v in VRM1_FROM_VRM0.items()}
_SKIN_SHINE = (0.05, 18.0)  # rig_import.KIND_SHINE["skin"]

Progress = Callable[[int, int, str], None]


def read_gltf(path: str | os.PathLike, *, name: str | None = None, progress: Progress | None = None) -> Character:
    """Read a glTF 2.0 (``.gltf``), GLB (``.glb``) or VRM (``.vrm``) file as a character with its parts.

    Parameters
    ----------
    path : the file; the format is found from its bytes (GLB magic ``glTF``, else JSON)
    name : character name; default the VRM title, else the file stem
    progress : callable(i, n, label) after each mesh instance is read, i from 1

    Returns
    -------
    Character, units "m", with skeleton, look, expressions (VRM only) and layout; ``metadata``
    holds ``settings["source"]`` (format, meta, credits, warnings, node_from_file, …) and metrics.

    Raises
    ------
    GltfError
        (an InputFileError) naming the file and the JSON field path: bad container, bad or
        out-of-range data, unsupported required extension, primitive mode other than triangles.
    FileNotFoundError
        the file is missing.
    """
    path = Path(path)
    f = read_gltf_file(path)
    reader = _Reader(f)
    with np.errstate(all="ignore"):  # overflow shows as non-finite values, refused by name below
        return reader.read(name, progress)


class _Reader:
    def __init__(self, f: GltfFile) -> None:
        self.f = f
        self.doc = f.doc
        self.warnings: list[str] = []
        self.vrm0 = _ext(self.doc).get("VRM")
        self.vrm1 = _ext(self.doc).get("VRMC_vrm")
        if self.vrm0 is not None and not isinstance(self.vrm0, dict):
            f.fail("extensions.VRM", "expected an object")
        if self.vrm1 is not None and not isinstance(self.vrm1, dict):
            f.fail("extensions.VRMC_vrm", "expected an object")
        if self.vrm1 is not None:
            self.format = "vrm1"
        elif self.vrm0 is not None:
            self.format = "vrm0"
        else:
            self.format = "glb" if f.is_glb else "gltf"
        self.turn = self.format == "vrm0"

    # -- top level ---------------------------------------------------------------
    def read(self, name: str | None, progress: Progress | None) -> Character:
        f = self.f
        self._extensions()
        self._nodes()
        geo = self._geometry(progress)
        materials = self._materials(geo["material_used"])
        look = self._look(geo, materials)
        shape_names, deltas = self._shapes(geo)
        expressions = self._expressions(geo, shape_names)
        skeleton = Skeleton(tuple(self.node_names), self.parent.astype(np.int32), self.rest_local.astype(np.float32),
                            geo["vertex_nodes"].astype(np.uint16), geo["vertex_weights"].astype(np.float32),
                            self._bones())
        vertices = geo["vertices"]
        if not np.isfinite(vertices).all() or np.abs(vertices).max() > np.finfo(np.float32).max:
            f.fail("nodes", "the node transforms take vertices beyond the float32 range")
        for where, arr in (("morph targets", deltas["delta_positions"]), ("morph targets", deltas["delta_normals"]),
                           ("materials", look.base_color), ("materials", look.emissive), ("materials", look.alpha),
                           ("materials", look.shading), ("materials", look.uv_transform),
                           ("TEXCOORD_0", look.uv), ("COLOR_0", geo["colors"]),
                           ("skins", skeleton.rest_local), ("skins", skeleton.vertex_weights)):
            if not np.isfinite(arr).all():
                f.fail(where, "values beyond the float32 range (or NaN) after transforming; a character stores "
                              "finite float32")
        pivot, pivot_rule = self._pivot(skeleton, vertices)
        meta = self._meta()
        source = {
            "format": self.format,
            "file": f.path.name,
            "turned_y180": self.turn,
            "meta": meta,
            "credits": _credits(self.format, meta),
            "extensions_used": list(self.doc.get("extensionsUsed", [])),
            "vrm_extension": self.vrm0 if self.vrm0 is not None else self.vrm1,
            "node_from_file": [int(i) for i in self.node_from_file],
            "mesh_nodes": [int(s) for _, s in sorted(x for v in geo["instance_of_mesh"].values() for x in v)],
            "mesh_from_file": [m for _, m in sorted((mi, m) for m, v in geo["instance_of_mesh"].items()
                                                    for mi, _ in v)],
            "default_weights": geo["default_weights"],
            "warnings": self.warnings,
            "pivot_rule": pivot_rule,
        }
        if not isinstance(name, str) or not name:
            name = str(meta.get("title") or meta.get("name") or f.path.stem) or f.path.stem
        settings = {"source": source, "name": name}
        metrics = {"n_vertices": int(len(vertices)), "n_triangles": int(len(geo["triangles"])),
                   "n_meshes": len(geo["mesh_names"]), "n_primitives": int(len(geo["primitives"])),
                   "n_nodes": len(self.node_names), "n_joints": geo["n_joints"],
                   "n_textures": len(look.texture_names), "n_expressions": len(expressions.names),
                   "stored_deltas": int(deltas["delta_offsets"][-1])}
        with naming_file(f.path):
            try:
                return Character(
                    name=name, units="m",
                    vertices=vertices.astype(np.float32),
                    triangles=geo["triangles"].astype(np.uint32),
                    triangle_material=geo["triangle_material"].astype(np.uint16),
                    vertex_color=geo["colors"].astype(np.float32),
                    material_names=materials["names"],
                    material_params=materials["params"],
                    pivot=pivot.astype(np.float32),
                    shape_names=shape_names,
                    **deltas,
                    metadata={"settings": settings, "metrics": metrics,
                              "input_hash": hash_inputs(f.path, *f.external)},
                    skeleton=skeleton, look=look,
                    expressions=expressions if (self.vrm0 is not None or self.vrm1 is not None) else None,
                    layout=Layout(tuple(geo["mesh_names"]), geo["primitives"]),
                    normals=geo["normals"].astype(np.float32) if geo["file_normals"] else None,
                )
            except TablesError as exc:  # a value the file allows but a character cannot hold
                raise GltfError(f.path, exc.field, exc.problem) from None

    def warn(self, text: str) -> None:
        self.warnings.append(text)

    def _extensions(self) -> None:
        f = self.f
        used = self.doc.get("extensionsUsed", [])
        required = self.doc.get("extensionsRequired", [])
        for key, value in (("extensionsUsed", used), ("extensionsRequired", required)):
            if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
                f.fail(key, "expected an array of extension names")
        refused = [e for e in required if e not in SUPPORTED_EXTENSIONS]
        if refused:
            f.fail("extensionsRequired", f"{', '.join(refused)}: required by the file but not supported by this "
                                         f"reader (supported: {', '.join(sorted(SUPPORTED_EXTENSIONS))})")
        ignored = [e for e in used if e not in SUPPORTED_EXTENSIONS and e not in QUIET_EXTENSIONS]
        if ignored:
            self.warn(f"extensions used but not honoured (ignored): {', '.join(ignored)}")

    # -- nodes -----------------------------------------------------------------
    def _nodes(self) -> None:
        """Scene roots, the hierarchy renumbered parents first, local and world rest matrices."""
        f = self.f
        nodes = f.items("nodes")
        for i in range(len(nodes)):
            f.obj("nodes", i, f"nodes[{i}]")
        parent_of = np.full(len(nodes), -1, dtype=np.int64)
        for i, node in enumerate(nodes):
            children = f.get(node, "children", list, f"nodes[{i}]", [])
            for k, c in enumerate(children):
                f.obj("nodes", c, f"nodes[{i}].children[{k}]")
                if parent_of[c] >= 0 or c == i:
                    f.fail(f"nodes[{i}].children[{k}]", f"node {c} has two parents or is its own child")
                parent_of[c] = i
        roots = self._scene_roots(parent_of)
        order: list[int] = []
        seen = np.zeros(len(nodes), dtype=bool)
        stack = list(reversed(roots))
        while stack:  # depth first, parents before children; a cycle shows as a revisit
            i = stack.pop()
            if seen[i]:
                f.fail(f"nodes[{i}]", "the node hierarchy has a cycle")
            seen[i] = True
            order.append(i)
            stack.extend(reversed(nodes[i].get("children", [])))
        if len(order) > 65535:
            f.fail("nodes", f"{len(order)} nodes in the scene; a character holds at most 65535")
        self.node_from_file = np.array(order, dtype=np.int64)
        self.stored_of = {file_i: s for s, file_i in enumerate(order)}
        self.parent = np.array([self.stored_of.get(int(parent_of[i]), -1) for i in order], dtype=np.int64)
        local = np.array([self._local(i, nodes[i]) for i in order]).reshape(-1, 4, 4)
        if self.turn:
            local[self.parent < 0] = TURN_Y180 @ local[self.parent < 0]
        self.rest_local = local
        world = np.empty_like(local)
        for s in range(len(order)):
            p = int(self.parent[s])
            world[s] = local[s] if p < 0 else world[p] @ local[s]
        if not np.isfinite(world).all():
            f.fail("nodes", "the node transforms overflow (non-finite world matrices)")
        self.world = world  # stored frame (turned for VRM 0.x)
        names, used = [], set()
        for i in order:
            base = nodes[i].get("name") if isinstance(nodes[i].get("name"), str) and nodes[i]["name"] else f"node{i}"
            n, k = base, 1
            while n in used:
                k += 1
                n = f"{base}#{k}"
            used.add(n)
            names.append(n)
        self.node_names = names

    def _scene_roots(self, parent_of: np.ndarray) -> list[int]:
        f = self.f
        scenes = f.items("scenes")
        if scenes:
            s = f.get(self.doc, "scene", int, "", 0)
            scene = f.obj("scenes", s, "scene")
            roots = f.get(scene, "nodes", list, f"scenes[{s}]", [])
            for k, r in enumerate(roots):
                f.obj("nodes", r, f"scenes[{s}].nodes[{k}]")
                if parent_of[r] >= 0:
                    f.fail(f"scenes[{s}].nodes[{k}]", f"node {r} is a root of the scene but has a parent")
            if len(set(roots)) != len(roots):
                f.fail(f"scenes[{s}].nodes", "a root node is listed twice")
            return list(roots)
        return [int(i) for i in np.flatnonzero(parent_of < 0)]

    def _local(self, i: int, node: dict) -> np.ndarray:
        f, w = self.f, f"nodes[{i}]"
        if "matrix" in node:
            m = f.numbers(node, "matrix", 16, w, None).reshape(4, 4).T  # column-major
            if not np.allclose(m[3], (0, 0, 0, 1)):
                f.fail(f"{w}.matrix", "the last row must be (0, 0, 0, 1) (an affine transform)")
            return m
        t = f.numbers(node, "translation", 3, w, [0, 0, 0])
        q = f.numbers(node, "rotation", 4, w, [0, 0, 0, 1])
        s = f.numbers(node, "scale", 3, w, [1, 1, 1])
        if np.linalg.norm(q) < 1e-6:
            f.fail(f"{w}.rotation", "a zero quaternion is not a rotation")
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(q) * s[None, :]
        m[:3, 3] = t
        return m

    # -- geometry ----------------------------------------------------------------
    def _geometry(self, progress: Progress | None) -> dict:
        f = self.f
        instances = [(s, i) for s, i in enumerate(self.node_from_file) if "mesh" in self.doc["nodes"][i]]
        out: dict[str, Any] = {"vertices": [], "normals": [], "uv": [], "colors": [], "nodes": [], "weights": [],
                               "triangles": [], "triangle_material": [], "primitives": [], "mesh_names": [],
                               "targets": [], "default_weights": {}, "material_used": set(),
                               "instance_of_mesh": {}, "n_joints": 0, "file_normals": True}
        n_v = n_t = 0
        joints_used: set[int] = set()
        for k, (s, i) in enumerate(instances, start=1):
            node = self.doc["nodes"][i]
            m = f.get(node, "mesh", int, f"nodes[{i}]")
            mesh = f.obj("meshes", m, f"nodes[{i}].mesh")
            mw = f"meshes[{m}]"
            mesh_name = mesh.get("name") if isinstance(mesh.get("name"), str) and mesh["name"] else f"mesh{m}"
            unique, copy = mesh_name, 1
            while unique in out["mesh_names"]:
                copy += 1
                unique = f"{mesh_name}#{copy}"
            mesh_index = len(out["mesh_names"])
            out["mesh_names"].append(unique)
            out["instance_of_mesh"].setdefault(m, []).append((mesh_index, s))
            skin = self._skin(node, i)
            prims = f.get(mesh, "primitives", list, mw)
            if not prims:
                f.fail(f"{mw}.primitives", "a mesh needs at least one primitive")
            mesh_names_t = _target_names(mesh.get("extras"))
            groups: dict[str, tuple[int, int]] = {}  # attribute key -> (first vertex, n vertices)
            for p, prim in enumerate(prims):
                pw = f"{mw}.primitives[{p}]"
                if not isinstance(prim, dict):
                    f.fail(pw, "expected an object")
                mode = f.get(prim, "mode", int, pw, 4)
                if mode != 4:
                    f.fail(f"{pw}.mode", f"{mode} ({_MODES.get(mode, 'unknown')}): only triangle lists (4) are read")
                attrs = f.get(prim, "attributes", dict, pw)
                targets = f.get(prim, "targets", list, pw, [])
                key = json.dumps([attrs, targets], sort_keys=True)
                if key not in groups:
                    siblings = [(f"{mw}.primitives[{q}]", pr) for q, pr in enumerate(prims)
                                if isinstance(pr, dict) and pr.get("mode", 4) == 4
                                and json.dumps([pr.get("attributes"), pr.get("targets", [])], sort_keys=True) == key]
                    g = self._vertices(attrs, targets, pw, skin, s, siblings)
                    groups[key] = (n_v, len(g["positions"]))
                    out["vertices"].append(g["positions"])
                    out["normals"].append(g["normals"])
                    out["file_normals"] &= g["from_file"]
                    out["uv"].append(g["uv"])
                    out["colors"].append(g["colors"])
                    out["nodes"].append(g["nodes"])
                    out["weights"].append(g["weights"])
                    joints_used.update(np.unique(g["nodes"][g["weights"] > 0]).tolist() if skin is not None else [])
                    names = _target_names(prim.get("extras")) or mesh_names_t
                    for t, (dp, dn) in enumerate(g["targets"]):
                        tname = names[t] if t < len(names) and isinstance(names[t], str) and names[t] \
                            else f"{mesh_name}.{t}"
                        out["targets"].append((tname, n_v, dp, dn))
                    n_v += len(g["positions"])
                first, count = groups[key]
                tri = self._indices(prim, pw, count) + first
                material = prim.get("material", -1)
                if material != -1:
                    f.obj("materials", material, f"{pw}.material")
                out["material_used"].add(material)
                out["triangles"].append(tri)
                out["triangle_material"].append(np.full(len(tri), material, dtype=np.int64))
                out["primitives"].append([first, count, n_t, len(tri), mesh_index, material])
                n_t += len(tri)
            weights = mesh.get("weights")
            if isinstance(weights, list) and weights:
                names = mesh_names_t or _target_names(prims[0].get("extras"))
                for t, wt in enumerate(weights):
                    if isinstance(wt, (int, float)) and not isinstance(wt, bool) and wt:
                        tname = names[t] if t < len(names) and isinstance(names[t], str) and names[t] \
                            else f"{mesh_name}.{t}"
                        out["default_weights"][tname] = float(wt)
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
        return out

    def _skin(self, node: dict, i: int) -> dict | None:
        """Per skin: joint stored indices and the joint matrices G(joint) IBM (stored frame)."""
        if "skin" not in node:
            return None
        f = self.f
        s = f.get(node, "skin", int, f"nodes[{i}]")
        skin = f.obj("skins", s, f"nodes[{i}].skin")
        w = f"skins[{s}]"
        joints = f.get(skin, "joints", list, w)
        if not joints:
            f.fail(f"{w}.joints", "a skin needs at least one joint")
        stored = []
        for k, j in enumerate(joints):
            f.obj("nodes", j, f"{w}.joints[{k}]")
            if j not in self.stored_of:
                f.fail(f"{w}.joints[{k}]", f"node {j} is not in the default scene")
            stored.append(self.stored_of[j])
        stored = np.asarray(stored, dtype=np.int64)
        if "inverseBindMatrices" in skin:
            ibm = f.accessor(skin["inverseBindMatrices"], f"{w}.inverseBindMatrices")
            if ibm.shape != (len(joints), 4, 4):
                f.fail(f"{w}.inverseBindMatrices", f"expected {len(joints)} MAT4, found shape {ibm.shape}")
            if not np.isfinite(ibm).all():
                f.fail(f"{w}.inverseBindMatrices", "contains NaN or infinite values")
        else:
            ibm = np.tile(np.eye(4), (len(joints), 1, 1))
        return {"joints": stored, "matrices": self.world[stored] @ ibm, "where": w}

    def _vertices(self, attrs: dict, targets: list, pw: str, skin: dict | None, node: int,
                  siblings: list[tuple[str, dict]]) -> dict:
        """The vertices of the primitives ``siblings`` (all sharing these attributes) in the stored frame."""
        f = self.f
        aw = f"{pw}.attributes"
        if "POSITION" not in attrs:
            f.fail(f"{aw}.POSITION", "missing: a primitive needs positions")
        pos = self._attr(attrs, "POSITION", aw, (3,))
        n = len(pos)
        if not np.isfinite(pos).all():
            bad = int(np.argmax(~np.isfinite(pos).all(axis=1)))
            f.fail(f"{aw}.POSITION", f"vertex {bad} is {pos[bad].tolist()} (NaN or infinite)")
        normals = self._attr(attrs, "NORMAL", aw, (3,), n) if "NORMAL" in attrs else None
        uv = self._attr(attrs, "TEXCOORD_0", aw, (2,), n) if "TEXCOORD_0" in attrs else np.zeros((n, 2))
        if "COLOR_0" in attrs:
            c = self._attr(attrs, "COLOR_0", aw, (3, 4), n)
            colors = np.clip(c[:, :3], 0.0, 1.0)
        else:
            colors = np.ones((n, 3))
        if "JOINTS_1" in attrs or "WEIGHTS_1" in attrs:
            self.warn(f"{aw}: JOINTS_1/WEIGHTS_1 ignored (a character keeps four influences per vertex)")
        if skin is not None and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
            joints = self._attr(attrs, "JOINTS_0", aw, (4,), n, as_float=False)
            if np.any(joints < 0) or np.any(joints >= len(skin["joints"])):
                bad = int(joints.max())
                f.fail(f"{aw}.JOINTS_0", f"joint {bad} is out of range for the {len(skin['joints'])} joints of "
                                         f"{skin['where']}")
            weights = self._attr(attrs, "WEIGHTS_0", aw, (4,), n)
            weights = np.clip(np.nan_to_num(weights, nan=0.0, posinf=0.0, neginf=0.0), 0.0, None)
            total = weights.sum(axis=1)
            empty = total <= 0
            if empty.any():
                self.warn(f"{aw}.WEIGHTS_0: {int(empty.sum())} vertices without weight follow their first joint")
                weights[empty] = (1, 0, 0, 0)
                total[empty] = 1.0
            weights = weights / total[:, None]
            weights[weights < 1e-7] = 0.0  # float32 dust; renormalise once more
            weights = weights / weights.sum(axis=1, keepdims=True)
            matrix = np.einsum("vk,vkij->vij", weights, skin["matrices"][joints])
            nodes = skin["joints"][joints]
        else:
            if skin is not None:
                self.warn(f"{pw}: skinned node but no JOINTS_0/WEIGHTS_0: the mesh follows its node")
            matrix = np.broadcast_to(self.world[node], (n, 4, 4))
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
        tri = np.concatenate([self._indices(pr, w, n) for w, pr in siblings]) if normals is None else None
        if normals is not None:
            nrm = _unit(np.einsum("vij,vj->vi", normal_m, normals))
        else:
            nrm = _vertex_normals(world, tri)
        out_targets = []
        for t, target in enumerate(targets):
            tw = f"{pw}.targets[{t}]"
            if not isinstance(target, dict):
                f.fail(tw, "expected an object")
            dp = self._attr(target, "POSITION", tw, (3,), n) if "POSITION" in target else np.zeros((n, 3))
            if not np.isfinite(dp).all():
                f.fail(f"{tw}.POSITION", "contains NaN or infinite deltas")
            dpw = np.einsum("vij,vj->vi", lin, dp)
            if "NORMAL" in target and normals is not None:
                dn = self._attr(target, "NORMAL", tw, (3,), n)
                dnw = _unit(np.einsum("vij,vj->vi", normal_m, normals + dn)) - nrm
            elif normals is None:
                dnw = _vertex_normals(world + dpw, tri) - nrm
            else:
                dnw = np.zeros((n, 3))
            dnw[np.linalg.norm(dnw, axis=1) <= NORMAL_TOLERANCE] = 0.0  # as the OBJ import: not stored
            out_targets.append((dpw, dnw))
        from_file = normals is not None and bool(np.all(np.abs(np.linalg.norm(nrm, axis=1) - 1.0) < 1e-3))
        if normals is not None and not from_file:
            self.warn(f"{aw}.NORMAL: zero or non-finite normals; the character's normals are computed instead")
        return {"positions": world, "normals": nrm, "from_file": from_file, "uv": uv, "colors": colors,
                "nodes": nodes,
                "weights": weights, "targets": out_targets}

    def _attr(self, attrs: dict, key: str, where: str, widths: tuple, n: int | None = None,
              as_float: bool = True) -> np.ndarray:
        a = self.f.accessor(attrs[key], f"{where}.{key}", as_float=as_float)
        if a.ndim != 2 or a.shape[1] not in widths:
            self.f.fail(f"{where}.{key}", f"accessor {attrs[key]} has {a.shape[1:] or '1'} components per "
                                          f"element, expected {' or '.join(map(str, widths))}")
        if n is not None and len(a) != n:
            self.f.fail(f"{where}.{key}", f"accessor {attrs[key]} has {len(a)} elements but POSITION has {n}")
        return a

    def _indices(self, prim: dict, pw: str, n: int) -> np.ndarray:
        f = self.f
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
    def _shapes(self, geo: dict) -> tuple[tuple[str, ...], dict]:
        order: list[str] = []
        per: dict[str, list] = {}
        for tname, first, dp, dn in geo["targets"]:
            if tname not in per:
                order.append(tname)
                per[tname] = []
            keep = np.flatnonzero(np.any(dp != 0, axis=1) | np.any(dn != 0, axis=1))
            per[tname].append((keep + first, dp[keep], dn[keep]))
        offsets, idx, pos, nrm = [0], [], [], []
        for tname in order:
            i = np.concatenate([k for k, _, _ in per[tname]])
            o = np.argsort(i, kind="stable")
            idx.append(i[o])
            pos.append(np.concatenate([p for _, p, _ in per[tname]])[o])
            nrm.append(np.concatenate([q for _, _, q in per[tname]])[o])
            offsets.append(offsets[-1] + len(i))
        geo["target_names"] = order
        return tuple(order), {
            "delta_offsets": np.asarray(offsets, dtype=np.int64),
            "delta_indices": (np.concatenate(idx) if idx else np.zeros(0)).astype(np.uint32),
            "delta_positions": (np.concatenate(pos) if pos else np.zeros((0, 3))).astype(np.float32),
            "delta_normals": (np.concatenate(nrm) if nrm else np.zeros((0, 3))).astype(np.float32),
        }

    # -- materials and look --------------------------------------------------------
    def _materials(self, used: set) -> dict:
        f = self.f
        mats = f.items("materials")
        names, params = [], []
        seen: set[str] = set()
        for i, m in enumerate(mats):
            f.obj("materials", i, f"materials[{i}]")
            base = m.get("name") if isinstance(m.get("name"), str) and m["name"] else f"material{i}"
            n, k = base, 1
            while n in seen:
                k += 1
                n = f"{base}#{k}"
            seen.add(n)
            names.append(n)
            params.append(self._material_kind(m, i))
        self.default_material = None
        if -1 in used:  # primitives without a material: the spec's default material, appended
            self.default_material = len(names)
            n = "default"
            while n in seen:
                n += "_"
            names.append(n)
            params.append([_SKIN_SHINE[0], _SKIN_SHINE[1], MATERIAL_KINDS["skin"], 0.0])
        if not names:
            names, params = ["default"], [[_SKIN_SHINE[0], _SKIN_SHINE[1], MATERIAL_KINDS["skin"], 0.0]]
        return {"names": tuple(names), "params": np.asarray(params, dtype=np.float32)}

    def _material_kind(self, m: dict, i: int) -> list[float]:
        """[specular, shininess, kind, 0] of material ``i``: skin, unless ``extras.facepuppet`` (written by
        ``export-character``) names another kind; a malformed entry is warned about and ignored."""
        skin = [_SKIN_SHINE[0], _SKIN_SHINE[1], float(MATERIAL_KINDS["skin"]), 0.0]
        extras = m.get("extras")
        ours = extras.get("facepuppet") if isinstance(extras, dict) else None
        if ours is None:
            return skin
        kind, spec, shine = (ours.get(k) if isinstance(ours, dict) else None for k in ("kind", "specular", "shininess"))
        numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) and x >= 0
                      for x in (spec, shine))
        if kind not in MATERIAL_KINDS or not numbers:
            self.warn(f"materials[{i}].extras.facepuppet: expected a kind of {sorted(MATERIAL_KINDS)} and "
                      f"finite specular/shininess >= 0, got {ours!r}; read as skin")
            return skin
        return [float(spec), float(shine), float(MATERIAL_KINDS[kind]), 0.0]

    def _look(self, geo: dict, materials: dict) -> Look:
        f = self.f
        if self.default_material is not None:
            geo["triangle_material"][geo["triangle_material"] == -1] = self.default_material
            p = geo["primitives"]
            p[p[:, 5] == -1, 5] = self.default_material
        mats = f.items("materials")
        n_m = len(materials["names"])
        base = np.ones((n_m, 4))
        emissive = np.zeros((n_m, 3))
        alpha = np.tile([ALPHA_MODES["OPAQUE"], 0.5], (n_m, 1))
        shading = np.zeros((n_m, 8))
        texture = np.full(n_m, -1, dtype=np.int64)
        uvt = np.tile(IDENTITY_UV_TRANSFORM, (n_m, 1))
        textures: dict[int, int] = {}  # glTF texture index -> stored texture index
        mtoon0 = self._vrm0_material_properties(mats)
        for i, m in enumerate(mats):
            w = f"materials[{i}]"
            pbr = f.get(m, "pbrMetallicRoughness", dict, w, {})
            base[i] = f.numbers(pbr, "baseColorFactor", 4, f"{w}.pbrMetallicRoughness", [1, 1, 1, 1])
            emissive[i] = f.numbers(m, "emissiveFactor", 3, w, [0, 0, 0])
            mode = f.get(m, "alphaMode", str, w, "OPAQUE")
            if mode not in ALPHA_MODES:
                f.fail(f"{w}.alphaMode", f"{mode!r} is not OPAQUE, MASK or BLEND")
            cutoff = f.get(m, "alphaCutoff", float, w, 0.5)
            alpha[i] = (ALPHA_MODES[mode], cutoff)
            shading[i, 1] = 1.0 if f.get(m, "doubleSided", bool, w, False) else 0.0
            ext = _ext(m)
            strength = ext.get("KHR_materials_emissive_strength")
            if isinstance(strength, dict):
                emissive[i] *= f.get(strength, "emissiveStrength", float, f"{w}.extensions."
                                     "KHR_materials_emissive_strength", 1.0)
            if "KHR_materials_unlit" in ext:
                shading[i, 0] = SHADING["unlit"]
            if "baseColorTexture" in pbr:
                info = f.get(pbr, "baseColorTexture", dict, f"{w}.pbrMetallicRoughness")
                tw = f"{w}.pbrMetallicRoughness.baseColorTexture"
                t = f.get(info, "index", int, tw)
                f.obj("textures", t, f"{tw}.index")
                if f.get(info, "texCoord", int, tw, 0) != 0:
                    self.warn(f"{tw}.texCoord: TEXCOORD_{info['texCoord']} asked for; only TEXCOORD_0 is read")
                if t not in textures:
                    textures[t] = len(textures)
                texture[i] = textures[t]
                tt = _ext(info).get("KHR_texture_transform")
                if isinstance(tt, dict):
                    ttw = f"{tw}.extensions.KHR_texture_transform"
                    off = f.numbers(tt, "offset", 2, ttw, [0, 0])
                    rot = f.get(tt, "rotation", float, ttw, 0.0)
                    scale = f.numbers(tt, "scale", 2, ttw, [1, 1])
                    uvt[i] = (off[0], off[1], rot, scale[0], scale[1])
            mt1 = ext.get("VRMC_materials_mtoon")
            if isinstance(mt1, dict):
                mw = f"{w}.extensions.VRMC_materials_mtoon"
                shading[i, 0] = SHADING["toon"]
                shading[i, 2:5] = f.numbers(mt1, "shadeColorFactor", 3, mw, [0, 0, 0])
                shading[i, 5] = f.get(mt1, "shadingShiftFactor", float, mw, 0.0)
                shading[i, 6] = f.get(mt1, "shadingToonyFactor", float, mw, 0.9)
            elif i in mtoon0:
                shading[i, :] = mtoon0[i] if mtoon0[i] is not None else shading[i, :]
                if mtoon0[i] is not None:
                    shading[i, 1] = 1.0 if f.get(m, "doubleSided", bool, w, False) else 0.0
        names, info, pixels = self._textures(textures)
        return Look(uv=geo["uv"].astype(np.float32), base_color=base.astype(np.float32),
                    emissive=emissive.astype(np.float32), alpha=alpha.astype(np.float32),
                    shading=shading.astype(np.float32), texture=texture.astype(np.int32),
                    uv_transform=uvt.astype(np.float32), texture_names=names, texture_info=info,
                    texture_pixels=pixels)

    def _vrm0_material_properties(self, mats: list) -> dict:
        """VRM 0.x ``materialProperties`` (matched to glTF materials by name) -> shading rows.

        MToon 0.x: ``_ShadeColor`` (sRGB in the file, decoded to linear here), and the 0.x
        shading range [_ShadeShift, lerp(1, _ShadeShift, _ShadeToony)] re-expressed in VRM
        1.0's terms (``shadingToonyFactor`` = (2 − range width) / 2, ``shadingShiftFactor`` =
        −range centre), so that one shader draws both. Unlit VRM shaders -> unlit.
        """
        if self.vrm0 is None:
            return {}
        f = self.f
        props = self.vrm0.get("materialProperties", [])
        if not isinstance(props, list):
            f.fail("extensions.VRM.materialProperties", "expected an array")
        by_name = {m.get("name"): i for i, m in enumerate(mats) if isinstance(m, dict)}
        out: dict[int, np.ndarray | None] = {}
        for k, prop in enumerate(props):
            w = f"extensions.VRM.materialProperties[{k}]"
            if not isinstance(prop, dict):
                f.fail(w, "expected an object")
            i = by_name.get(prop.get("name"), k if k < len(mats) else None)
            if i is None:
                continue
            shader = prop.get("shader", "")
            row = np.zeros(8)
            if shader == "VRM/MToon":
                floats = f.get(prop, "floatProperties", dict, w, {})
                vectors = f.get(prop, "vectorProperties", dict, w, {})
                shade = f.numbers(vectors, "_ShadeColor", 4, f"{w}.vectorProperties", [0.97, 0.81, 0.86, 1])
                shift = f.get(floats, "_ShadeShift", float, f"{w}.floatProperties", 0.0)
                toony = f.get(floats, "_ShadeToony", float, f"{w}.floatProperties", 0.9)
                lo, hi = shift, 1.0 + (shift - 1.0) * toony
                row[0] = SHADING["toon"]
                row[2:5] = _srgb_to_linear(np.clip(shade[:3], 0, 1))
                row[5] = -(lo + hi) / 2
                row[6] = np.clip((2.0 - (hi - lo)) / 2, 0.0, 1.0)
                out[i] = row
            elif isinstance(shader, str) and shader.startswith("VRM/Unlit"):
                row[0] = SHADING["unlit"]
                out[i] = row
            else:
                out[i] = None  # VRM_USE_GLTFSHADER: the glTF material as it is
        return out

    def _textures(self, textures: dict[int, int]) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        f = self.f
        names, info, pixels = [], [], []
        first = 0
        used: set[str] = set()
        for t, _stored in sorted(textures.items(), key=lambda kv: kv[1]):
            tex = f.obj("textures", t, f"textures[{t}]")
            w = f"textures[{t}]"
            src = f.get(tex, "source", int, w, None)
            if src is None:
                f.fail(f"{w}.source", "missing: the texture has no PNG/JPEG image (KHR_texture_basisu and other "
                                      "image extensions are not read)")
            img = f.obj("images", src, f"{w}.source")
            iw = f"images[{src}]"
            rgba = self._decode_image(img, iw)
            sampler = [0, 0, 0, 0]
            if "sampler" in tex:
                s = f.obj("samplers", tex["sampler"], f"{w}.sampler")
                sampler = []
                for k, allowed in (("magFilter", _MAG), ("minFilter", _MIN), ("wrapS", _WRAP), ("wrapT", _WRAP)):
                    v = f.get(s, k, int, f"samplers[{tex['sampler']}]", 0)
                    if v and v not in allowed:
                        f.fail(f"samplers[{tex['sampler']}].{k}", f"{v} is not one of {sorted(allowed)}")
                    sampler.append(v)
            h, wd = rgba.shape[:2]
            base = img.get("name") if isinstance(img.get("name"), str) and img["name"] else f"image{src}"
            n, k = base, 1
            while n in used:
                k += 1
                n = f"{base}#{k}"
            used.add(n)
            names.append(n)
            info.append([first, wd, h, *sampler])
            pixels.append(rgba.reshape(-1, 4))
            first += wd * h
        return (tuple(names), np.asarray(info, dtype=np.int32).reshape(-1, 7),
                np.concatenate(pixels) if pixels else np.zeros((0, 4), np.uint8))

    def _decode_image(self, img: dict, iw: str) -> np.ndarray:
        from PIL import Image, UnidentifiedImageError

        f = self.f
        if "bufferView" in img:
            data, start, length, _ = f.view_bytes(f.get(img, "bufferView", int, iw), f"{iw}.bufferView")
            blob = data[start:start + length]
        elif "uri" in img:
            blob, _ = f.read_uri(f.get(img, "uri", str, iw), f"{iw}.uri")
        else:
            f.fail(iw, "missing: an image needs a uri or a bufferView")
        if not (blob[:8] == b"\x89PNG\r\n\x1a\n" or blob[:3] == b"\xff\xd8\xff"):
            f.fail(iw, f"not a PNG or JPEG image (mimeType {img.get('mimeType')!r}); only those are decoded")
        try:
            with _warnings.catch_warnings():
                _warnings.simplefilter("error", Image.DecompressionBombWarning)
                with Image.open(io.BytesIO(blob)) as im:
                    if im.width * im.height > 8192 * 8192:
                        f.fail(iw, f"{im.width}x{im.height} is larger than 8192x8192 texels")
                    return np.asarray(im.convert("RGBA"), dtype=np.uint8).copy()
        except GltfError:
            raise
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError, Image.DecompressionBombWarning,
                Image.DecompressionBombError) as exc:
            f.fail(iw, f"the image cannot be decoded ({str(exc)[:120]})")

    # -- VRM -------------------------------------------------------------------------
    def _bones(self) -> dict:
        f = self.f
        bones: dict[str, int] = {}
        if self.vrm1 is not None:
            hb = self.vrm1.get("humanoid", {}).get("humanBones", {}) if isinstance(self.vrm1.get("humanoid"),
                                                                                 dict) else {}
            w = "extensions.VRMC_vrm.humanoid.humanBones"
            if not isinstance(hb, dict):
                f.fail(w, "expected an object of bone name -> {node}")
            pairs = [(b, v.get("node") if isinstance(v, dict) else None, f"{w}.{b}.node") for b, v in hb.items()]
        elif self.vrm0 is not None:
            hb = self.vrm0.get("humanoid", {}).get("humanBones", []) if isinstance(self.vrm0.get("humanoid"),
                                                                                 dict) else []
            w = "extensions.VRM.humanoid.humanBones"
            if not isinstance(hb, list):
                f.fail(w, "expected an array of {bone, node}")
            pairs = [(v.get("bone") if isinstance(v, dict) else None, v.get("node") if isinstance(v, dict) else None,
                      f"{w}[{k}]") for k, v in enumerate(hb)]
        else:
            return bones
        for bone, node, where in pairs:
            if not isinstance(bone, str) or not bone:
                f.fail(where, "a human bone needs a bone name")
            f.obj("nodes", node, where)
            if node not in self.stored_of:
                self.warn(f"{where}: bone {bone!r} is node {node}, which is not in the default scene (dropped)")
                continue
            bones[bone] = int(self.stored_of[node])
        return bones

    def _expressions(self, geo: dict, shape_names: tuple[str, ...]) -> Expressions:
        shape_index = {n: i for i, n in enumerate(shape_names)}
        rows: list[tuple[str, str, list, list, list]] = []
        if self.vrm1 is not None:
            rows = self._vrm1_expressions(geo, shape_index)
        elif self.vrm0 is not None:
            rows = self._vrm0_expressions(geo, shape_index)
        names, presets, offsets, bs, bw, flags = [], [], [0], [], [], []
        for name, preset, shapes, weights, flag in rows:
            if name in names:
                self.warn(f"expression {name!r} appears twice; the first is kept")
                continue
            # One shape spans every mesh whose targets share its name, and VRM binds it once per mesh:
            # the binds of one shape are one bind (the largest, with a warning when the meshes differ).
            merged: dict[int, float] = {}
            for s, wt in zip(shapes, weights):
                if s in merged and abs(merged[s] - wt) > 1e-6:
                    self.warn(f"expression {name!r}: shape {shape_names[s]!r} is bound at {merged[s]:g} and "
                              f"{wt:g} on different meshes; one shape takes the larger")
                merged[s] = max(merged.get(s, 0.0), wt)
            names.append(name)
            presets.append(preset)
            bs.extend(merged)
            bw.extend(merged.values())
            offsets.append(len(bs))
            flags.append(flag)
        return Expressions(tuple(names), tuple(presets), np.asarray(offsets, dtype=np.int64),
                           np.asarray(bs, dtype=np.uint32), np.asarray(bw, dtype=np.float32),
                           np.asarray(flags, dtype=np.int32).reshape(-1, 4))

    def _target_name_of(self, mesh: int, index: int) -> str | None:
        meshes = self.doc.get("meshes", [])
        if not (isinstance(mesh, int) and 0 <= mesh < len(meshes)) or not isinstance(index, int):
            return None
        m = meshes[mesh]
        names = _target_names(m.get("extras"))
        prims = m.get("primitives") or [{}]
        if not names and isinstance(prims[0], dict):
            names = _target_names(prims[0].get("extras"))
        n_targets = max((len(p.get("targets", [])) for p in prims if isinstance(p, dict)), default=0)
        if not 0 <= index < n_targets:
            return None
        if index < len(names) and isinstance(names[index], str) and names[index]:
            return names[index]
        base = m.get("name") if isinstance(m.get("name"), str) and m["name"] else f"mesh{mesh}"
        return f"{base}.{index}"

    def _vrm0_expressions(self, geo: dict, shape_index: dict) -> list:
        f = self.f
        bsm = self.vrm0.get("blendShapeMaster", {})
        w = "extensions.VRM.blendShapeMaster.blendShapeGroups"
        groups = bsm.get("blendShapeGroups", []) if isinstance(bsm, dict) else None
        if not isinstance(groups, list):
            f.fail(w, "expected an array")

        def mesh_of(bind: dict, bw: str) -> tuple[int, str]:
            mesh = f.get(bind, "mesh", int, bw)
            return mesh, f"mesh {mesh}"

        rows = []
        for g, group in enumerate(groups):
            gw = f"{w}[{g}]"
            if not isinstance(group, dict):
                f.fail(gw, "expected an object")
            preset_name = f.get(group, "presetName", str, gw, "unknown").lower()
            preset = _VRM0_BY_LOWER.get(preset_name, "")
            name = preset or f.get(group, "name", str, gw, "") or f"expression{g}"
            shapes, weights = self._binds(f.get(group, "binds", list, gw, []), f"{gw}.binds", mesh_of, 100.0,
                                          shape_index)
            binary = 1 if f.get(group, "isBinary", bool, gw, False) else 0
            rows.append((name, preset, shapes, weights, [binary, 0, 0, 0]))
        return rows

    def _binds(self, binds: list, where: str, mesh_of: Callable[[dict, str], tuple[int | None, str]],
               full: float, shape_index: dict) -> tuple[list, list]:
        """(shapes, weights in 0..1) of a VRM expression's morph-target binds (``full``: the weight of 100 %);
        a bind naming no morph target of the scene is dropped with a warning."""
        f = self.f
        shapes, weights = [], []
        for b, bind in enumerate(binds):
            bw = f"{where}[{b}]"
            if not isinstance(bind, dict):
                f.fail(bw, "expected an object")
            mesh, label = mesh_of(bind, bw)
            index = f.get(bind, "index", int, bw)
            weight = f.get(bind, "weight", float, bw, full)
            tname = self._target_name_of(mesh, index)
            if tname is None or tname not in shape_index:
                self.warn(f"{bw}: {label} target {index} is not a morph target in the scene (dropped)")
                continue
            shapes.append(shape_index[tname])
            weights.append(float(np.clip(weight / full, 0.0, 1.0)))
        return shapes, weights

    def _vrm1_expressions(self, geo: dict, shape_index: dict) -> list:
        f = self.f

        def node_mesh(bind: dict, bw: str) -> tuple[int | None, str]:
            node = f.get(bind, "node", int, bw)
            return f.obj("nodes", node, f"{bw}.node").get("mesh"), f"node {node}"

        ex = self.vrm1.get("expressions", {})
        w = "extensions.VRMC_vrm.expressions"
        if not isinstance(ex, dict):
            f.fail(w, "expected an object")
        rows = []
        for group in ("preset", "custom"):
            table = ex.get(group, {})
            if not isinstance(table, dict):
                f.fail(f"{w}.{group}", "expected an object of name -> expression")
            for key, e in table.items():
                ew = f"{w}.{group}.{key}"
                if not isinstance(e, dict):
                    f.fail(ew, "expected an object")
                preset = _VRM0_FROM_VRM1.get(key, "") if group == "preset" else ""
                name = preset or key
                shapes, weights = self._binds(f.get(e, "morphTargetBinds", list, ew, []), f"{ew}.morphTargetBinds",
                                              node_mesh, 1.0, shape_index)
                flag = [1 if f.get(e, "isBinary", bool, ew, False) else 0]
                for k in ("overrideBlink", "overrideLookAt", "overrideMouth"):
                    v = f.get(e, k, str, ew, "none")
                    if v not in OVERRIDES:
                        f.fail(f"{ew}.{k}", f"{v!r} is not none, block or blend")
                    flag.append(OVERRIDES[v])
                rows.append((name, preset, shapes, weights, flag))
        return rows

    def _meta(self) -> dict:
        if self.vrm1 is not None:
            meta = self.vrm1.get("meta", {})
        elif self.vrm0 is not None:
            meta = self.vrm0.get("meta", {})
        else:
            meta = {k: v for k, v in self.doc.get("asset", {}).items() if k in ("copyright", "generator", "version")}
            extras = self.doc.get("asset", {}).get("extras")
            if isinstance(extras, dict):
                meta.update({k: v for k, v in extras.items() if k in ("title", "author", "license", "source")})
        return meta if isinstance(meta, dict) else {}

    def _pivot(self, skeleton: Skeleton, vertices: np.ndarray) -> tuple[np.ndarray, str]:
        if "head" in skeleton.bones:
            return self.world[skeleton.bones["head"]][:3, 3].copy(), "the head bone's rest position"
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        size, centre = hi - lo, (hi + lo) / 2
        return (np.array([centre[0], lo[1] + 0.35 * size[1], centre[2] - 0.1 * size[2]]),
                "bbox: centre x, min y + 0.35 height, centre z - 0.1 depth")


_MAG = frozenset({9728, 9729})
_MIN = frozenset({9728, 9729, 9984, 9985, 9986, 9987})
_WRAP = frozenset({33071, 33648, 10497})
_MODES = {0: "points", 1: "lines", 2: "line loop", 3: "line strip", 4: "triangles", 5: "triangle strip",
          6: "triangle fan"}


def _ext(o: Any) -> dict:
    e = o.get("extensions", {}) if isinstance(o, dict) else {}
    return e if isinstance(e, dict) else {}


def _target_names(extras: Any) -> list:
    names = extras.get("targetNames") if isinstance(extras, dict) else None
    return names if isinstance(names, list) else []


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


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _credits(fmt: str, meta: dict) -> str:
    """One line of attribution from the VRM meta (title, author(s), reference, licence) or glTF asset."""
    def s(key: str) -> str:
        v = meta.get(key)
        return v.strip() if isinstance(v, str) else ""

    if fmt == "vrm1":
        title = s("name")
        authors = meta.get("authors")
        author = ", ".join(a for a in authors if isinstance(a, str)) if isinstance(authors, list) else ""
        licence = s("licenseUrl")
        extra = s("copyrightInformation")
    elif fmt == "vrm0":
        title, author, extra = s("title"), s("author"), s("reference")
        licence = s("licenseName").replace("_", " ")  # CC_BY -> "CC BY" (VRM 0.x names carry no version)
        if licence in ("Other", "Redistribution Prohibited") and s("otherLicenseUrl"):
            licence = f"{licence} ({s('otherLicenseUrl')})"
    else:
        title, author, licence, extra = s("title"), s("author"), s("license"), s("copyright")
    parts = []
    if title and author:
        parts.append(f"{title} by {author}")
    elif title or author:
        parts.append(title or f"by {author}")
    if extra:
        parts.append(extra[0].lower() + extra[1:] if extra[:1].isupper() and extra.split()[0] in
                     ("Adapted", "Converted") else extra)
    if licence:
        parts.append(licence)
    return ", ".join(parts)


def print_summary(character: Character, seconds: float, out: Path, stream: Any = None) -> None:
    """The import summary of a glTF/VRM character (``import-rig``)."""
    stream = stream or sys.stdout
    src = character.source
    m = character.metadata.get("metrics", {})
    bones = character.skeleton.bones if character.skeleton is not None else {}
    head = "head" + ("" if "head" in bones else " (not found)")
    neck = "neck" + ("" if "neck" in bones else " (not found)")
    print(f"{out}: character '{character.name}' from {src.get('format')} {src.get('file')}: "
          f"{character.n_vertices} vertices, {len(character.triangles)} triangles, "
          f"{m.get('n_meshes')} meshes / {m.get('n_primitives')} primitives, metres"
          f"{', turned 180° about +Y (VRM 0.x faces -Z)' if src.get('turned_y180') else ''}\n"
          f"  shapes: {character.n_shapes}; expressions: {character.n_expressions}; "
          f"nodes: {m.get('n_nodes')} ({m.get('n_joints')} joints used); textures: {m.get('n_textures')}; "
          f"humanoid {head}, {neck}", file=stream)
    meta = src.get("meta") or {}
    if src.get("format") in ("vrm0", "vrm1"):
        keys = (("title", "version", "author", "licenseName", "allowedUserName", "commercialUssageName",
                 "violentUssageName", "sexualUssageName") if src.get("format") == "vrm0" else
                ("name", "version", "authors", "licenseUrl", "avatarPermission", "commercialUsage",
                 "allowExcessivelyViolentUsage", "allowExcessivelySexualUsage", "allowRedistribution"))
        shown = ", ".join(f"{k}={meta[k]}" for k in keys if k in meta)
        print(f"  VRM meta: {shown}", file=stream)
    if character.credits:
        print(f"  credits: {character.credits}", file=stream)
    for line in src.get("warnings", []):
        print(f"  warning: {line}", file=stream)
    print(f"  file {out.stat().st_size / 1e6:.2f} MB, {seconds:.2f} s", file=stream)
