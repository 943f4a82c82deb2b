"""A character back out as glTF 2.0 (GLB or .gltf) or VRM 0.x / 1.0 (``export-character``).

What is written (glTF 2.0 spec; VRM 0.x ``VRM`` extension; VRM 1.0 ``VRMC_vrm`` and
``VRMC_materials_mtoon``):

* **meshes**: one glTF mesh per :class:`~facepuppet.runtime.character_parts.Layout`
  mesh, one primitive per Layout primitive; primitives of a mesh that share a
  vertex range share their vertex accessors. A character without a Layout (an
  OBJ rig) is one mesh with one primitive per material. Attributes: POSITION
  (with min/max), NORMAL (the character's own ``normals`` where it has them,
  else area-weighted from the triangles, since a glTF without them is drawn
  flat), TEXCOORD_0 (with
  a Look), COLOR_0 (the vertex colours, when not all white), JOINTS_0 and
  WEIGHTS_0 (with a Skeleton).
* **morph targets**: per mesh, one target for each shape that moves a vertex of
  that mesh (POSITION and NORMAL deltas), named in ``mesh.extras.targetNames``;
  every primitive of the mesh has the same targets (zero where the shape does
  not move its vertices). A target that moves few of a primitive's vertices is
  a sparse accessor, one that moves none an accessor without a buffer view
  (zeros, as the spec says). A shape that moves nothing at all is kept as a
  zero target of the first mesh so its name survives.
* **skin**: the Skeleton's nodes (parents first, the stored order) with their
  local rest matrices as translation/rotation/scale when they decompose without
  shear, else as ``matrix``; one skin whose joints are the nodes any vertex
  follows with a non-zero weight; inverse bind matrices = the inverse of each
  joint's rest world transform (vertices are stored in the world rest pose, so
  at rest every joint matrix is the identity). Each mesh goes back on the node
  that held it in the file when the reader kept it (``settings.source.mesh_nodes``),
  else on a new root node of its own; that node carries the skin (a skinned
  mesh's node transform is ignored).
* **textures**: PNG, lossless, re-encoded from the stored texels; samplers from
  the stored codes.
* **materials**: baseColorFactor/-Texture (with KHR_texture_transform when not
  the identity), emissive, alphaMode/alphaCutoff, doubleSided, KHR_materials_unlit;
  metallicFactor 0 and a roughness from the stored shininess (Blinn-Phong n ->
  GGX: roughness = (2 / (n + 2))^(1/4)), since a character keeps no metal/roughness.
  An OBJ rig's ``hidden`` material is written BLEND with alpha 0 (kept, not drawn);
  its thin layers (eye occlusion, films, lashes) BLEND and double-sided, with the fade the
  renderer gives them (``render.layers.vertex_opacity``) as COLOR_0 alpha (RGBA), so any glTF
  viewer draws them see-through. A material kind other than skin (eye, teeth, lashes ...) and
  its specular/shininess go in ``material.extras.facepuppet`` for the importer.
  Toon materials: VRM 0.x ``materialProperties`` (``VRM/MToon``) or VRM 1.0
  ``VRMC_materials_mtoon``; the 0.x shading range is converted back from the
  1.0 terms the character stores.
* **VRM**: meta (``settings.source.meta``, converted between 0.x and 1.0 field
  names when the version changes), humanoid (``Skeleton.bones``), expressions
  (0.x ``blendShapeGroups`` with weights 0..100; 1.0 ``expressions`` preset /
  custom with ``morphTargetBinds`` {node, index, weight}, isBinary, overrides),
  and a custom expression for each shape whose name is one of ARKit's 52 and
  has no expression of its name yet (perfect sync: ``EyeBlinkLeft`` …). The
  raw extension kept on import (``settings.source.vrm_extension``) goes back
  for its other parts (0.x firstPerson / secondaryAnimation, 1.0 firstPerson /
  lookAt) with node indices remapped through ``settings.source.node_from_file``
  (and first-person mesh annotations through ``mesh_nodes`` / ``mesh_from_file``
  when the reader kept them; dropped with a warning otherwise).
* **frame**: glTF units are metres (cm and mm are scaled); a VRM 0.x file faces
  −Z, so for VRM 0.x output everything is turned 180° about +Y (vertices,
  normals, deltas; the node transforms by turning the roots, so that every
  world transform becomes ``T·G``, the inverse of the reader's turn).
"""

from __future__ import annotations

import base64
import copy
import io
import json
import os
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.channels import ARKIT_NAMES, canonical, pascal
from facepuppet.runtime.character import MATERIAL_KINDS, Character
from facepuppet.runtime.character_parts import ALPHA_MODES, OVERRIDES, SHADING
from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.geometry import matrix_to_quat, vertex_normals
from facepuppet.runtime.outputs import atomic_path
from facepuppet.runtime.render.layers import LAYER_KINDS, has_layers, vertex_opacity
from facepuppet.runtime.vrm_names import VRM1_FROM_VRM0

__all__ = ["ExportError", "ExportSummary", "build_gltf", "encode_glb", "export_character", "output_format"]

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_COMPONENT = {np.dtype(np.float32): FLOAT, np.dtype(np.uint8): UBYTE, np.dtype(np.uint16): USHORT,
              np.dtype(np.uint32): UINT}
_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
TURN_Y180 = np.diag([-1.0, 1.0, -1.0, 1.0])
#: Humanoid bones VRM requires (1.0 spec, humanoid.md "required"; the same set satisfies UniVRM 0.x).
REQUIRED_BONES = ("hips", "spine", "head", "leftUpperLeg", "leftLowerLeg", "leftFoot", "rightUpperLeg",
                  "rightLowerLeg", "rightFoot", "leftUpperArm", "leftLowerArm", "leftHand", "rightUpperArm",
                  "rightLowerArm", "rightHand")
_VRM1_PRESETS = frozenset(VRM1_FROM_VRM0.values()) | {"surprised"}
_ARKIT = frozenset(ARKIT_NAMES)
_ALPHA_NAME = {v: k for k, v in ALPHA_MODES.items()}
_KIND_NAME = {v: k for k, v in MATERIAL_KINDS.items()}
_OVERRIDE_NAME = {v: k for k, v in OVERRIDES.items()}
_SPARSE_FRACTION = 0.5  # a target is sparse when its sparse form is under half the dense one
GENERATOR = "facepuppet export-character"

Progress = Callable[[int, int, str], None]


class ExportError(FacepuppetError, ValueError):
    """The character cannot be written as asked (a VRM without a humanoid, an unknown suffix, …)."""


@dataclass
class ExportSummary:
    """What ``export_character`` wrote (for the command's summary)."""

    path: Path
    format: str
    n_meshes: int = 0
    n_primitives: int = 0
    n_nodes: int = 0
    n_joints: int = 0
    n_materials: int = 0
    n_textures: int = 0
    n_targets: int = 0
    n_sparse_targets: int = 0
    n_expressions: int = 0
    added_expressions: list[str] = field(default_factory=list)
    turned_y180: bool = False
    bytes: int = 0
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)


def output_format(path: str | os.PathLike, character: Character, vrm: int | None = None) -> str:
    """"glb", "gltf", "vrm0" or "vrm1" from the output suffix (and ``vrm`` for a .vrm)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".vrm":
        if vrm is None:
            vrm = 1 if character.source.get("format") == "vrm1" else 0
        if vrm not in (0, 1):
            raise ExportError(f"--vrm {vrm}: VRM versions are 0 (0.x) and 1 (1.0)")
        return f"vrm{vrm}"
    if vrm is not None:
        raise ExportError(f"--vrm {vrm}: only for a .vrm output, not {Path(path).name}")
    if suffix in (".glb", ".gltf"):
        return suffix[1:]
    raise ExportError(f"{path}: unknown output format {suffix or '(no suffix)'}; name a .vrm, .glb or .gltf file")


def export_character(character: Character, path: str | os.PathLike, *, vrm: int | None = None,
                     progress: Progress | None = None) -> ExportSummary:
    """Write ``character`` to ``path`` (.glb, .gltf or .vrm, see :func:`output_format`), atomically."""
    start = time.perf_counter()
    path = Path(path)
    fmt = output_format(path, character, vrm)
    doc, blob, summary = build_gltf(character, fmt, progress=progress)
    summary.path = path
    if fmt == "gltf":
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        data = json.dumps(doc, ensure_ascii=False, indent=1).encode("utf-8")
    else:
        data = encode_glb(doc, blob)
    with atomic_path(path) as temp:
        temp.write_bytes(data)
    summary.bytes = len(data)
    summary.seconds = time.perf_counter() - start
    return summary


def encode_glb(doc: dict, blob: bytes) -> bytes:
    """A GLB: 12-byte header, JSON chunk padded with spaces, BIN chunk padded with zeros (4-byte aligned)."""
    js = json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(js), GLB_JSON) + js
    if blob:
        chunks += struct.pack("<II", len(blob), GLB_BIN) + blob
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


# -- the buffer --------------------------------------------------------------------------------
class _Buffer:
    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = -self.size % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.size += pad
        v = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.parts.append(data)
        self.size += len(data)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, a: np.ndarray, target: int | None = ARRAY_BUFFER, minmax: bool = False,
                 normalized: bool = False) -> int:
        a = np.ascontiguousarray(a)
        width = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
        acc = {"bufferView": self.view(a.tobytes(), target), "componentType": _COMPONENT[a.dtype],
               "count": int(len(a)), "type": _TYPES[width]}
        if normalized:
            acc["normalized"] = True
        if minmax:
            flat = a.reshape(len(a), width)
            acc["min"], acc["max"] = _numbers(flat.min(axis=0)), _numbers(flat.max(axis=0))
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def sparse_vec3(self, count: int, idx: np.ndarray, values: np.ndarray) -> int:
        """A VEC3 float accessor of ``count`` zeros but ``values`` at ``idx`` (sorted); min/max included."""
        values = np.ascontiguousarray(values, dtype=np.float32)
        acc: dict[str, Any] = {"componentType": FLOAT, "count": int(count), "type": "VEC3"}
        if len(idx):
            lo, hi = values.min(axis=0), values.max(axis=0)
            if len(idx) < count:
                lo, hi = np.minimum(lo, 0), np.maximum(hi, 0)
            itype = np.uint16 if count <= 65535 else np.uint32
            acc["sparse"] = {"count": int(len(idx)),
                             "indices": {"bufferView": self.view(idx.astype(itype).tobytes()),
                                         "componentType": _COMPONENT[np.dtype(itype)]},
                             "values": {"bufferView": self.view(values.tobytes())}}
        else:
            lo = hi = np.zeros(3, np.float32)
        acc["min"], acc["max"] = _numbers(lo), _numbers(hi)
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.parts)


def _numbers(a: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=np.float32).tolist()]


def _srgb_encode(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def _trs(m: np.ndarray) -> dict:
    """A node's local transform as glTF translation/rotation/scale when it decomposes, else ``matrix``."""
    m = np.asarray(m, dtype=np.float64)
    out: dict[str, Any] = {}
    if np.allclose(m, np.eye(4), atol=1e-7):
        return out
    lin = m[:3, :3]
    scale = np.linalg.norm(lin, axis=0)
    ok = np.allclose(m[3], (0, 0, 0, 1), atol=1e-7) and np.all(scale > 1e-12)
    if ok:
        rot = lin / scale
        ok = np.linalg.det(rot) > 0 and np.allclose(rot.T @ rot, np.eye(3), atol=1e-5)
    if not ok:
        return {"matrix": [float(x) for x in m.T.reshape(-1)]}  # column-major
    t = m[:3, 3]
    if np.any(np.abs(t) > 0):
        out["translation"] = [float(x) for x in t]
    q = matrix_to_quat(rot)
    if not np.allclose(q, (0, 0, 0, 1), atol=1e-9):
        out["rotation"] = [float(x) for x in q]
    if not np.allclose(scale, 1.0, atol=1e-7):
        out["scale"] = [float(x) for x in scale]
    return out


# -- the document ------------------------------------------------------------------------------
class _Exporter:
    def __init__(self, c: Character, fmt: str, progress: Progress | None) -> None:
        self.c, self.fmt, self.progress = c, fmt, progress
        self.buf = _Buffer()
        self.turn = fmt == "vrm0"
        self.summary = ExportSummary(Path(), fmt, turned_y180=self.turn)
        self.ext_used: set[str] = set()

    def warn(self, text: str) -> None:
        self.summary.warnings.append(text)

    # frames
    def _points(self, v: np.ndarray, scale: float = 1.0) -> np.ndarray:
        out = np.asarray(v, dtype=np.float64) * scale
        if self.turn:
            out = out * (-1.0, 1.0, -1.0)
        return out.astype(np.float32)

    def build(self) -> tuple[dict, bytes]:
        c = self.c
        if self.fmt.startswith("vrm"):
            self._check_humanoid()
        scale = _UNIT_SCALE.get(c.units)
        if scale is None:
            raise ExportError(f"character {c.name!r}: units {c.units!r} are not m, cm or mm")
        self.scale = scale
        self.vertices = self._points(c.vertices, scale)
        if c.normals is not None:  # the file's own normals (hard edges, custom normals), turned as the points
            self.normals = self._points(c.normals)
        else:
            self.normals = vertex_normals(self.vertices, c.triangles.astype(np.int64))
        no_normal = np.linalg.norm(self.normals, axis=1) < 0.5
        self.normals[no_normal] = (0.0, 0.0, -1.0 if self.turn else 1.0)
        # an OBJ rig's thin layers: the fade the renderer gives them, as COLOR_0 alpha
        self.opacity = vertex_opacity(c).astype(np.float32) if c.look is None and has_layers(c) else None
        self.delta_pos = self._points(c.delta_positions, scale)
        self.delta_nrm = self._points(c.delta_normals)
        doc: dict[str, Any] = {"asset": self._asset(), "scene": 0}
        nodes = self._nodes()
        self.primitives = self._layout()
        materials, textures = self._materials()
        meshes = self._meshes()
        kept = self._mesh_nodes(len(meshes))
        self.host: list[int] = []
        for m in range(len(meshes)):
            if kept is not None:  # back on the node that held it in the file
                node = nodes[kept[m]]
                node["mesh"] = m
            else:
                node = {"name": self._host_names[m], "mesh": m}
                nodes.append(node)
            if c.skeleton is not None:
                node["skin"] = 0
            self.host.append(kept[m] if kept is not None else len(nodes) - 1)
        roots = [j for j in range(self.n_skeleton_nodes) if c.skeleton.parent[j] < 0] if c.skeleton else []
        doc["scenes"] = [{"nodes": roots + list(range(self.n_skeleton_nodes, len(nodes)))}]
        doc["nodes"] = nodes
        doc["meshes"] = meshes
        if c.skeleton is not None:
            doc["skins"] = [self._skin()]
        doc["materials"] = materials
        doc.update(textures)
        if self.fmt == "vrm0":
            doc["extensions"] = {"VRM": self._vrm0(materials)}
            self.ext_used.add("VRM")
        elif self.fmt == "vrm1":
            doc["extensions"] = {"VRMC_vrm": self._vrm1()}
            self.ext_used.add("VRMC_vrm")
        doc["accessors"] = self.buf.accessors
        doc["bufferViews"] = self.buf.views
        blob = self.buf.data()
        doc["buffers"] = [{"byteLength": len(blob)}]
        if self.ext_used:
            doc["extensionsUsed"] = sorted(self.ext_used)
        s = self.summary
        s.n_meshes, s.n_nodes, s.n_materials = len(meshes), len(nodes), len(materials)
        s.n_primitives = sum(len(m["primitives"]) for m in meshes)
        return {k: v for k, v in doc.items() if v != [] or k in ("buffers",)}, blob

    def _asset(self) -> dict:
        asset = {"version": "2.0", "generator": GENERATOR}
        meta = self.c.source.get("meta", {}) if isinstance(self.c.source.get("meta"), dict) else {}
        if self.c.source.get("format") in ("gltf", "glb", None):
            if isinstance(meta.get("copyright"), str):
                asset["copyright"] = meta["copyright"]
            extras = {k: meta[k] for k in ("title", "author", "license", "source") if isinstance(meta.get(k), str)}
            if extras:
                asset["extras"] = extras
        return asset

    # nodes and skin
    def _nodes(self) -> list[dict]:
        k = self.c.skeleton
        self.n_skeleton_nodes = 0 if k is None else k.n_nodes
        if k is None:
            return []
        t = TURN_Y180 if self.turn else np.eye(4)
        nodes = []
        children: list[list[int]] = [[] for _ in range(k.n_nodes)]
        for j in range(k.n_nodes):
            if k.parent[j] >= 0:
                children[int(k.parent[j])].append(j)
        for j in range(k.n_nodes):
            local = np.asarray(k.rest_local[j], dtype=np.float64).copy()
            local[:3, 3] *= self.scale
            if k.parent[j] < 0:  # turning the whole scene: the roots carry the turn, children are unchanged
                local = t @ local
            node: dict[str, Any] = {"name": k.names[j], **_trs(local)}
            if children[j]:
                node["children"] = children[j]
            nodes.append(node)
        return nodes

    def _mesh_nodes(self, n_meshes: int) -> list[int] | None:
        """``settings.source.mesh_nodes``: the stored node that held each Layout mesh in the file, when the
        reader kept it and it is usable (one distinct skeleton node per mesh); None: each mesh gets a new
        root node."""
        hint = self.c.source.get("mesh_nodes")
        if hint is None or self.c.skeleton is None:
            return None
        ok = (isinstance(hint, list) and len(hint) == n_meshes and len(set(map(str, hint))) == n_meshes
              and all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n < self.n_skeleton_nodes
                      for n in hint))
        if not ok:
            self.warn(f"settings.source.mesh_nodes {hint!r} is not one distinct node per mesh "
                      f"({n_meshes} meshes, {self.n_skeleton_nodes} nodes): each mesh gets a node of its own")
            return None
        return [int(n) for n in hint]

    def _skin(self) -> dict:
        k = self.c.skeleton
        t = TURN_Y180 if self.turn else np.eye(4)
        world = k.global_transforms()
        world[:, :3, 3] *= self.scale
        joints = self.joints
        ibm = np.stack([np.linalg.inv(t @ world[j]) for j in joints])
        ibm[:, 3] = (0, 0, 0, 1)  # exact affine bottom row
        cols = np.ascontiguousarray(np.transpose(ibm, (0, 2, 1)), dtype=np.float32).reshape(len(joints), 16)
        acc = self.buf.accessor(cols, target=None)
        self.summary.n_joints = len(joints)
        return {"joints": [int(j) for j in joints], "inverseBindMatrices": acc}

    # layout
    def _layout(self) -> list[tuple[int, int, np.ndarray, int, int]]:
        """(first vertex, n vertices, triangles (k, 3) global, mesh, material) per primitive; sets mesh names."""
        c = self.c
        out = []
        if c.layout is not None and len(c.layout.primitives):
            for first, n, t0, nt, mesh, mat in c.layout.primitives.tolist():
                out.append((first, n, c.triangles[t0:t0 + nt], mesh, mat))
            mesh_names = list(c.layout.mesh_names)
        else:
            for mat in range(len(c.material_names)):
                tri = c.triangles[c.triangle_material == mat]
                if len(tri):
                    out.append((0, c.n_vertices, tri, 0, mat))
            if not out:
                out.append((0, c.n_vertices, c.triangles[:0], 0, 0))
            mesh_names = [c.name or "mesh"]
        self.mesh_names = mesh_names
        taken = set(c.skeleton.names) if c.skeleton is not None else set()
        self._host_names = []
        for name in mesh_names:
            unique, k = name, 1
            while unique in taken:
                k += 1
                unique = f"{name}#{k}"
            taken.add(unique)
            self._host_names.append(unique)
        if c.skeleton is not None:
            w = c.skeleton.vertex_weights
            self.joints = np.unique(c.skeleton.vertex_nodes[w > 0]).astype(np.int64)
            if not len(self.joints):
                self.joints = np.zeros(1, np.int64)
        return out

    # meshes
    def _meshes(self) -> list[dict]:
        c = self.c
        n_meshes = len(self.mesh_names)
        by_mesh: list[list[tuple]] = [[] for _ in range(n_meshes)]
        for p in self.primitives:
            by_mesh[p[3]].append(p)
        group_of = np.full(c.n_vertices, -1, np.int64)
        mesh_of_group: list[int] = []
        groups: dict[tuple[int, int], int] = {}
        for first, n, _, mesh, _ in self.primitives:
            if (first, n) not in groups:
                groups[(first, n)] = len(groups)
                mesh_of_group.append(mesh)
                group_of[first:first + n] = groups[(first, n)]
        # shapes per mesh: those with a delta on one of its vertices, in shape order
        self.targets: list[list[int]] = [[] for _ in range(n_meshes)]
        mog = np.asarray(mesh_of_group + [-1])
        orphan = []
        for s in range(c.n_shapes):
            sl = c.shape_slice(s)
            g = group_of[c.delta_indices[sl]]
            meshes = np.unique(mog[g[g >= 0]]) if len(g) else np.zeros(0, np.int64)
            if not len(meshes):
                orphan.append(s)
            for m in meshes.tolist():
                self.targets[m].append(s)
        if orphan and n_meshes:
            first_mesh = next((m for m in range(n_meshes) if by_mesh[m]), 0)
            self.targets[first_mesh] = sorted(self.targets[first_mesh] + orphan)
        self.target_index = [{s: k for k, s in enumerate(t)} for t in self.targets]
        shared: dict[tuple[int, int], dict] = {}
        meshes = []
        done = 0
        total = sum(len(p) for p in by_mesh)
        defaults = c.source.get("default_weights", {})
        for m in range(n_meshes):
            prims = []
            for first, n, tri, _, mat in by_mesh[m]:
                key = (first, n)
                if key not in shared:
                    shared[key] = self._vertex_accessors(first, n, self.targets[m])
                attrs, targets = shared[key]
                local = np.asarray(tri, dtype=np.int64) - first
                if len(local) and (local.min() < 0 or local.max() >= n):
                    raise ExportError(f"layout: a triangle of mesh {self.mesh_names[m]!r} uses a vertex outside "
                                      f"its primitive's range {first}..{first + n - 1}")
                prim: dict[str, Any] = {"attributes": dict(attrs), "mode": 4, "material": int(mat)}
                if len(local):
                    itype = np.uint16 if n <= 65535 else np.uint32
                    prim["indices"] = self.buf.accessor(local.astype(itype).reshape(-1), ELEMENT_ARRAY_BUFFER)
                if targets:
                    prim["targets"] = [dict(t) for t in targets]
                prims.append(prim)
                done += 1
                if self.progress is not None:
                    self.progress(done, total, self.mesh_names[m])
            if not prims:
                continue
            mesh: dict[str, Any] = {"name": self.mesh_names[m], "primitives": prims}
            if self.targets[m]:
                names = [c.shape_names[s] for s in self.targets[m]]
                mesh["extras"] = {"targetNames": names}
                if isinstance(defaults, dict) and any(defaults.get(n) for n in names):
                    mesh["weights"] = [float(defaults.get(n, 0.0)) for n in names]
            meshes.append(mesh)
        if len(meshes) != n_meshes:
            raise ExportError("layout: a mesh without primitives; every Layout mesh needs at least one")
        return meshes

    def _vertex_accessors(self, first: int, n: int, shapes: list[int]) -> tuple[dict, list[dict]]:
        c, buf = self.c, self.buf
        sl = slice(first, first + n)
        attrs = {"POSITION": buf.accessor(self.vertices[sl], minmax=True), "NORMAL": buf.accessor(self.normals[sl])}
        if c.look is not None:
            attrs["TEXCOORD_0"] = buf.accessor(np.asarray(c.look.uv[sl], np.float32))
        colour = np.asarray(c.vertex_color[sl], np.float32)
        if c.look is None and self.opacity is not None:  # RGBA: the thin layers' fade in alpha
            colour = np.c_[colour, self.opacity[sl]]
        if c.look is None or not np.allclose(colour, 1.0, atol=1e-6):
            attrs["COLOR_0"] = buf.accessor(np.clip(colour, 0.0, 1.0))
        if c.skeleton is not None:
            k = c.skeleton
            joint_of = np.zeros(k.n_nodes, np.int64)
            joint_of[self.joints] = np.arange(len(self.joints))
            w = np.asarray(k.vertex_weights[sl], np.float64)
            w = np.where(w > 0, w, 0.0)
            w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-30)
            j = np.where(w > 0, joint_of[k.vertex_nodes[sl].astype(np.int64)], 0)
            jtype = np.uint8 if len(self.joints) <= 256 else np.uint16
            attrs["JOINTS_0"] = buf.accessor(j.astype(jtype))
            attrs["WEIGHTS_0"] = buf.accessor(w.astype(np.float32))
        targets = []
        for s in shapes:
            ss = c.shape_slice(s)
            idx = c.delta_indices[ss].astype(np.int64)
            inside = (idx >= first) & (idx < first + n)
            local = idx[inside] - first
            order = np.argsort(local, kind="stable")
            local = local[order]
            dp = self.delta_pos[ss][inside][order]
            dn = self.delta_nrm[ss][inside][order]
            if len(local) * 16 < _SPARSE_FRACTION * n * 12:
                t = {"POSITION": buf.sparse_vec3(n, local, dp), "NORMAL": buf.sparse_vec3(n, local, dn)}
                self.summary.n_sparse_targets += 1
            else:
                dense_p = np.zeros((n, 3), np.float32)
                dense_n = np.zeros((n, 3), np.float32)
                dense_p[local], dense_n[local] = dp, dn
                t = {"POSITION": buf.accessor(dense_p, minmax=True), "NORMAL": buf.accessor(dense_n)}
            targets.append(t)
            self.summary.n_targets += 1
        return attrs, targets

    # materials and textures
    def _materials(self) -> tuple[list[dict], dict]:
        c, lk = self.c, self.c.look
        mats = []
        for i, name in enumerate(c.material_names):
            shine = float(c.material_params[i, 1])
            rough = float(np.clip((2.0 / (max(shine, 0.0) + 2.0)) ** 0.25, 0.0, 1.0))
            pbr: dict[str, Any] = {"metallicFactor": 0.0, "roughnessFactor": round(rough, 6)}
            mat: dict[str, Any] = {"name": name, "pbrMetallicRoughness": pbr}
            kind = int(round(float(c.material_params[i, 2])))
            if kind != MATERIAL_KINDS["skin"]:  # read back by the importer; other readers ignore extras
                mat["extras"] = {"facepuppet": {"kind": _KIND_NAME.get(kind, "skin"),
                                                "specular": float(c.material_params[i, 0]),
                                                "shininess": float(c.material_params[i, 1])}}
            if lk is None:
                if kind == MATERIAL_KINDS["hidden"]:
                    pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 0.0]
                    mat["alphaMode"] = "BLEND"
                elif kind in LAYER_KINDS:  # thin see-through layers: COLOR_0 alpha holds their fade
                    mat["alphaMode"] = "BLEND"
                    mat["doubleSided"] = True
                mats.append(mat)
                continue
            base = [float(x) for x in lk.base_color[i]]
            if base != [1.0, 1.0, 1.0, 1.0]:
                pbr["baseColorFactor"] = base
            if int(lk.texture[i]) >= 0:
                info: dict[str, Any] = {"index": int(lk.texture[i])}
                uvt = [float(x) for x in lk.uv_transform[i]]
                if not np.allclose(uvt, (0, 0, 0, 1, 1), atol=0):
                    info["extensions"] = {"KHR_texture_transform": {"offset": uvt[:2], "rotation": uvt[2],
                                                                    "scale": uvt[3:]}}
                    self.ext_used.add("KHR_texture_transform")
                pbr["baseColorTexture"] = info
            if np.any(lk.emissive[i] != 0):
                mat["emissiveFactor"] = [float(x) for x in lk.emissive[i]]
            mode = _ALPHA_NAME[int(lk.alpha[i, 0])]
            if mode != "OPAQUE":
                mat["alphaMode"] = mode
            if mode == "MASK":
                mat["alphaCutoff"] = float(lk.alpha[i, 1])
            if lk.shading[i, 1] > 0.5:
                mat["doubleSided"] = True
            shading = int(lk.shading[i, 0])
            if shading == SHADING["unlit"]:
                mat["extensions"] = {"KHR_materials_unlit": {}}
                self.ext_used.add("KHR_materials_unlit")
            elif shading == SHADING["toon"] and self.fmt == "vrm1":
                mt = {"specVersion": "1.0", "shadeColorFactor": [float(x) for x in lk.shading[i, 2:5]],
                      "shadingShiftFactor": float(lk.shading[i, 5]), "shadingToonyFactor": float(lk.shading[i, 6])}
                if int(lk.texture[i]) >= 0:
                    mt["shadeMultiplyTexture"] = {"index": int(lk.texture[i])}
                mat["extensions"] = {"VRMC_materials_mtoon": mt}
                self.ext_used.add("VRMC_materials_mtoon")
            mats.append(mat)
        return mats, self._textures()

    def _textures(self) -> dict:
        lk = self.c.look
        if lk is None or not len(lk.texture_names):
            return {}
        from PIL import Image

        images, textures, samplers = [], [], []
        sampler_of: dict[tuple, int] = {}
        for t, name in enumerate(lk.texture_names):
            png = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(lk.image(t)), "RGBA").save(png, format="PNG", compress_level=4)
            images.append({"name": name, "mimeType": "image/png", "bufferView": self.buf.view(png.getvalue())})
            codes = tuple(int(x) for x in lk.texture_info[t, 3:7])
            if codes not in sampler_of:
                sampler_of[codes] = len(samplers)
                samplers.append({k: v for k, v in zip(("magFilter", "minFilter", "wrapS", "wrapT"), codes) if v})
            textures.append({"name": name, "source": t, "sampler": sampler_of[codes]})
        self.summary.n_textures = len(textures)
        return {"images": images, "textures": textures, "samplers": samplers}

    # VRM
    def _check_humanoid(self) -> None:
        c = self.c
        if c.skeleton is None:
            raise ExportError(f"character {c.name!r}: a VRM needs a humanoid skeleton and this character has none "
                              f"(it came from {c.source.get('format', 'an OBJ rig')}); missing bones: "
                              f"{', '.join(REQUIRED_BONES)}. Export it as .glb instead")
        missing = [b for b in REQUIRED_BONES if b not in c.skeleton.bones]
        if missing:
            raise ExportError(f"character {c.name!r}: a VRM humanoid needs the bones {', '.join(missing)}, which "
                              "the character's skeleton does not name; export it as .glb instead")

    def _expression_rows(self) -> list[tuple[str, str, list[tuple[int, float]], np.ndarray]]:
        """(name, VRM 0.x preset or "", [(shape, weight)], flags) for each expression to write."""
        c = self.c
        rows = []
        have: set[str] = set()
        if c.expressions is not None:
            e = c.expressions
            for i, name in enumerate(e.names):
                s, w = e.binds(i)
                rows.append((name, e.presets[i], list(zip(s.tolist(), w.tolist())), e.flags[i]))
                have.add(name)
                have.add(canonical(name))
        for s, name in enumerate(c.shape_names):
            key = canonical(name)
            if key in _ARKIT and pascal(name) not in have and key not in have:
                rows.append((pascal(name), "", [(s, 1.0)], np.zeros(4, np.int32)))
                have.update((pascal(name), key))
                self.summary.added_expressions.append(pascal(name))
        self.summary.n_expressions = len(rows)
        return rows

    def _binds(self, binds: list[tuple[int, float]]) -> list[tuple[int, int, float]]:
        """(mesh, target index, weight) of each bind: a shape on several meshes binds on each."""
        out = []
        for s, w in binds:
            for m, index in enumerate(self.target_index):
                if s in index:
                    out.append((m, index[s], float(w)))
        return out

    def _node_map(self) -> Callable[[Any], int | None]:
        src = self.c.source.get("node_from_file")
        n = self.n_skeleton_nodes
        inverse = {int(o): s for s, o in enumerate(src)} if isinstance(src, list) else {i: i for i in range(n)}

        def remap(node: Any) -> int | None:
            if isinstance(node, bool) or not isinstance(node, int):
                return None
            s = inverse.get(node)
            return s if s is not None and s < n else None
        return remap

    def _raw(self, fmt: str) -> dict:
        raw = self.c.source.get("vrm_extension")
        if self.c.source.get("format") != fmt or not isinstance(raw, dict):
            return {}
        return copy.deepcopy(raw)

    def _vrm0(self, materials: list[dict]) -> dict:
        bones = self.c.skeleton.bones
        raw = self._raw("vrm0")
        remap = self._node_map()
        out: dict[str, Any] = {"exporterVersion": GENERATOR, "specVersion": "0.0", "meta": self._meta0()}
        humanoid = raw.get("humanoid") if isinstance(raw.get("humanoid"), dict) else {}
        humanoid = {k: v for k, v in humanoid.items() if k != "humanBones"}
        humanoid["humanBones"] = [{"bone": b, "node": int(n), "useDefaultValues": True} for b, n in bones.items()]
        out["humanoid"] = humanoid
        first = raw.get("firstPerson") if isinstance(raw.get("firstPerson"), dict) else {}
        if "firstPersonBone" in first:
            node = remap(first["firstPersonBone"])
            first["firstPersonBone"] = node if node is not None else int(bones["head"])
        else:
            first.setdefault("firstPersonBone", int(bones["head"]))
            first.setdefault("firstPersonBoneOffset", {"x": 0.0, "y": 0.06, "z": 0.0})
        first["meshAnnotations"] = self._annotations0(first.get("meshAnnotations"))
        out["firstPerson"] = first
        groups = []
        for name, preset, binds, flags in self._expression_rows():
            groups.append({"name": name, "presetName": preset.lower() if preset else "unknown",
                           "binds": [{"mesh": m, "index": k, "weight": float(np.clip(w, 0, 1) * 100.0)}
                                     for m, k, w in self._binds(binds)],
                           "materialValues": [], "isBinary": bool(flags[0])})
        out["blendShapeMaster"] = {"blendShapeGroups": groups}
        out["secondaryAnimation"] = self._secondary0(raw.get("secondaryAnimation"), remap)
        out["materialProperties"] = [self._material0(i, m) for i, m in enumerate(materials)]
        return out

    def _annotations0(self, raw: Any) -> list:
        """VRM 0.x firstPerson.meshAnnotations ({mesh: file mesh index}) onto the written meshes, through
        ``settings.source.mesh_from_file`` (the file mesh of each Layout mesh) when the reader kept it."""
        if not isinstance(raw, list) or not raw:
            return []
        of_file = self.c.source.get("mesh_from_file")
        if not (isinstance(of_file, list) and len(of_file) == len(self.mesh_names)):
            self.warn("firstPerson.meshAnnotations dropped: the character does not keep which file mesh each "
                      "of its meshes was (VRM applications then use their automatic first-person view)")
            return []
        out = []
        for a in raw:
            if isinstance(a, dict):
                out += [{**a, "mesh": m} for m, f in enumerate(of_file) if f == a.get("mesh")]
        return out

    def _annotations1(self, raw: Any, remap: Callable[[Any], int | None]) -> list:
        """VRM 1.0 firstPerson.meshAnnotations ({node: file node}) onto the nodes the meshes are written on."""
        if not isinstance(raw, list):
            return []
        out = []
        for a in raw:
            node = remap(a.get("node")) if isinstance(a, dict) else None
            if node is not None and node in self.host:
                out.append({**a, "node": node})
            else:
                self.warn(f"firstPerson.meshAnnotations: {a!r} dropped: its node does not hold a written mesh "
                          "(the reader did not keep settings.source.mesh_nodes)")
        return out

    def _secondary0(self, raw: Any, remap: Callable[[Any], int | None]) -> dict:
        if not isinstance(raw, dict):
            return {"boneGroups": [], "colliderGroups": []}
        colliders, new_index = [], {}
        for k, g in enumerate(raw.get("colliderGroups", []) if isinstance(raw.get("colliderGroups"), list) else []):
            node = remap(g.get("node")) if isinstance(g, dict) else None
            if node is None:
                self.warn(f"secondaryAnimation.colliderGroups[{k}] dropped: its node is not in the character")
                continue
            new_index[k] = len(colliders)
            colliders.append({**g, "node": node})
        groups = []
        for k, g in enumerate(raw.get("boneGroups", []) if isinstance(raw.get("boneGroups"), list) else []):
            if not isinstance(g, dict):
                continue
            bones = [remap(b) for b in g.get("bones", []) if remap(b) is not None]
            if not bones:
                self.warn(f"secondaryAnimation.boneGroups[{k}] dropped: none of its bones is in the character")
                continue
            centre = g.get("center", -1)
            g = {**g, "bones": bones, "center": remap(centre) if remap(centre) is not None else -1,
                 "colliderGroups": [new_index[i] for i in g.get("colliderGroups", []) if i in new_index]}
            groups.append(g)
        return {**raw, "boneGroups": groups, "colliderGroups": colliders}

    def _material0(self, i: int, mat: dict) -> dict:
        lk = self.c.look
        prop = {"name": mat["name"], "shader": "VRM_USE_GLTFSHADER", "renderQueue": -1, "floatProperties": {},
                "vectorProperties": {}, "textureProperties": {}, "keywordMap": {}, "tagMap": {}}
        if lk is None:
            return prop
        mode = int(lk.alpha[i, 0])
        shading = int(lk.shading[i, 0])
        tag = ("Opaque", "TransparentCutout", "Transparent")[mode]
        queue = (2000, 2450, 3000)[mode]
        tex = int(lk.texture[i])
        ou, ov, _, su, sv = (float(x) for x in lk.uv_transform[i])
        main_st = [ou, 1.0 - sv - ov, su, sv]  # Unity's texture ST: v from the bottom
        if shading == SHADING["unlit"]:
            shader = ("VRM/UnlitTexture", "VRM/UnlitCutout", "VRM/UnlitTransparent")[mode]
            prop.update(shader=shader, renderQueue=queue, tagMap={"RenderType": tag},
                        vectorProperties={"_Color": [*_srgb_encode(lk.base_color[i, :3]).tolist(),
                                                     float(lk.base_color[i, 3])], "_MainTex": main_st},
                        floatProperties={"_Cutoff": float(lk.alpha[i, 1])},
                        textureProperties={"_MainTex": tex} if tex >= 0 else {})
            return prop
        if shading != SHADING["toon"]:
            return prop
        # the character keeps VRM 1.0's terms: shift = -(range centre), toony = (2 - width) / 2
        centre, width = -float(lk.shading[i, 5]), 2.0 - 2.0 * float(lk.shading[i, 6])
        lo, hi = centre - width / 2, centre + width / 2
        toony = float(np.clip((hi - 1.0) / (lo - 1.0), 0.0, 1.0)) if abs(lo - 1.0) > 1e-9 else 1.0
        double = lk.shading[i, 1] > 0.5
        blend = {0: (1, 0, 1), 1: (1, 0, 1), 2: (5, 10, 0)}[mode]  # _SrcBlend, _DstBlend, _ZWrite
        prop.update(
            shader="VRM/MToon", renderQueue=queue, tagMap={"RenderType": tag},
            keywordMap={k: True for k, on in (("_ALPHATEST_ON", mode == 1), ("_ALPHABLEND_ON", mode == 2)) if on},
            floatProperties={"_Cutoff": float(lk.alpha[i, 1]), "_ShadeShift": lo, "_ShadeToony": toony,
                             "_BlendMode": float(mode), "_CullMode": 0.0 if double else 2.0,
                             "_SrcBlend": float(blend[0]), "_DstBlend": float(blend[1]), "_ZWrite": float(blend[2])},
            vectorProperties={"_Color": [*_srgb_encode(lk.base_color[i, :3]).tolist(), float(lk.base_color[i, 3])],
                              "_ShadeColor": [*_srgb_encode(lk.shading[i, 2:5]).tolist(), 1.0],
                              "_EmissionColor": [*_srgb_encode(lk.emissive[i]).tolist(), 1.0], "_MainTex": main_st},
            textureProperties={"_MainTex": tex, "_ShadeTexture": tex} if tex >= 0 else {})
        return prop

    def _meta0(self) -> dict:
        src = self.c.source
        meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
        fmt = src.get("format")
        if fmt == "vrm0":
            out = {k: v for k, v in meta.items() if k != "texture"}  # the thumbnail's texture is not kept
        elif fmt == "vrm1":
            authors = meta.get("authors") if isinstance(meta.get("authors"), list) else []
            refs = meta.get("references") if isinstance(meta.get("references"), list) else []
            perm = {"onlyAuthor": "OnlyAuthor", "onlySeparatelyLicensedPerson": "ExplicitlyLicensedPerson",
                    "everyone": "Everyone"}
            out = {"title": meta.get("name", self.c.name), "version": meta.get("version", ""),
                   "author": ", ".join(str(a) for a in authors),
                   "contactInformation": meta.get("contactInformation", ""),
                   "reference": ", ".join(str(r) for r in refs),
                   "allowedUserName": perm.get(meta.get("avatarPermission"), "OnlyAuthor"),
                   "violentUssageName": "Allow" if meta.get("allowExcessivelyViolentUsage") else "Disallow",
                   "sexualUssageName": "Allow" if meta.get("allowExcessivelySexualUsage") else "Disallow",
                   "commercialUssageName": "Disallow" if meta.get("commercialUsage", "personalNonProfit")
                   == "personalNonProfit" else "Allow",
                   "licenseName": "Other", "otherLicenseUrl": meta.get("licenseUrl", "")}
        else:
            out = {"title": meta.get("title", self.c.name), "author": meta.get("author", ""),
                   "licenseName": "Other", "otherLicenseUrl": meta.get("license", ""),
                   "allowedUserName": "OnlyAuthor", "violentUssageName": "Disallow",
                   "sexualUssageName": "Disallow", "commercialUssageName": "Disallow"}
        return out

    def _meta1(self) -> dict:
        src = self.c.source
        meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
        fmt = src.get("format")
        if fmt == "vrm1":
            out = {k: v for k, v in meta.items() if k != "thumbnailImage"}  # the thumbnail's image is not kept
        elif fmt == "vrm0":
            perm = {"OnlyAuthor": "onlyAuthor", "ExplicitlyLicensedPerson": "onlySeparatelyLicensedPerson",
                    "Everyone": "everyone"}
            out = {"name": meta.get("title") or self.c.name, "version": meta.get("version", ""),
                   "authors": [meta["author"]] if meta.get("author") else [],
                   "contactInformation": meta.get("contactInformation", ""),
                   "references": [meta["reference"]] if meta.get("reference") else [],
                   "avatarPermission": perm.get(meta.get("allowedUserName"), "onlyAuthor"),
                   "allowExcessivelyViolentUsage": meta.get("violentUssageName") == "Allow",
                   "allowExcessivelySexualUsage": meta.get("sexualUssageName") == "Allow",
                   "commercialUsage": "corporation" if meta.get("commercialUssageName") == "Allow"
                   else "personalNonProfit",
                   "licenseUrl": "https://vrm.dev/licenses/1.0/"}
            licence = " ".join(str(meta.get(k, "")) for k in ("licenseName", "otherLicenseUrl")).strip()
            if licence:
                out["otherLicenseUrl" if meta.get("otherLicenseUrl") else "copyrightInformation"] = \
                    meta.get("otherLicenseUrl") or f"licence: {licence}"
        else:
            out = {"name": meta.get("title") or self.c.name,
                   "authors": [meta["author"]] if meta.get("author") else [],
                   "licenseUrl": "https://vrm.dev/licenses/1.0/"}
            if meta.get("license"):
                out["otherLicenseUrl"] = meta["license"]
        out.setdefault("name", self.c.name)
        if not out.get("authors"):
            out["authors"] = ["unknown"]  # required, one at least
            self.warn("meta: no author known; VRM 1.0 requires one, written as 'unknown'")
        out.setdefault("licenseUrl", "https://vrm.dev/licenses/1.0/")
        return out

    def _vrm1(self) -> dict:
        bones = self.c.skeleton.bones
        raw = self._raw("vrm1")
        out: dict[str, Any] = {"specVersion": "1.0", "meta": self._meta1(),
                               "humanoid": {"humanBones": {b: {"node": int(n)} for b, n in bones.items()}}}
        first = raw.get("firstPerson")
        if isinstance(first, dict):
            annotations = self._annotations1(first.get("meshAnnotations"), self._node_map())
            out["firstPerson"] = {**first, "meshAnnotations": annotations}
        if isinstance(raw.get("lookAt"), dict):
            out["lookAt"] = raw["lookAt"]
        preset, custom = {}, {}
        for name, p, binds, flags in self._expression_rows():
            e: dict[str, Any] = {"morphTargetBinds": [{"node": self.host[m], "index": k,
                                                       "weight": float(np.clip(w, 0, 1))}
                                                      for m, k, w in self._binds(binds)],
                                 "isBinary": bool(flags[0])}
            for col, key in ((1, "overrideBlink"), (2, "overrideLookAt"), (3, "overrideMouth")):
                e[key] = _OVERRIDE_NAME.get(int(flags[col]), "none")
            key = VRM1_FROM_VRM0.get(p, "") if p else (name if name in _VRM1_PRESETS else "")
            (preset if key else custom)[key or name] = e
        out["expressions"] = {"preset": preset, "custom": custom}
        return out


def build_gltf(character: Character, fmt: str, *,
               progress: Progress | None = None) -> tuple[dict, bytes, ExportSummary]:
    """The glTF JSON document, its binary buffer and a summary for ``character`` in ``fmt``
    ("glb", "gltf", "vrm0", "vrm1"); see the module doc for what goes where."""
    if fmt not in ("glb", "gltf", "vrm0", "vrm1"):
        raise ExportError(f"unknown export format {fmt!r}")
    ex = _Exporter(character, fmt, progress)
    doc, blob = ex.build()
    return doc, blob, ex.summary


def describe(summary: ExportSummary) -> str:
    """The command's summary of an export, a few lines."""
    s = summary
    lines = [f"{s.path}: {s.format.upper()}, {s.bytes / 1e6:.2f} MB, {s.seconds:.2f} s"
             + (" (turned 180° about +Y: VRM 0.x faces -Z)" if s.turned_y180 else ""),
             f"  {s.n_meshes} meshes, {s.n_primitives} primitives, {s.n_nodes} nodes ({s.n_joints} joints), "
             f"{s.n_materials} materials, {s.n_textures} textures",
             f"  morph targets: {s.n_targets} ({s.n_sparse_targets} sparse)"]
    if s.format.startswith("vrm"):
        added = f", {len(s.added_expressions)} added for perfect sync" if s.added_expressions else ""
        lines.append(f"  expressions: {s.n_expressions}{added}")
    lines += [f"  warning: {w}" for w in s.warnings]
    return "\n".join(lines)
