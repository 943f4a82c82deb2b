"""The written meshes: primitives, vertex attributes and morph targets, in the file's frame and units.

One glTF mesh per :class:`~facepuppet.runtime.model.character_parts.Layout` mesh,
one primitive per Layout primitive; primitives of a mesh that share a vertex
range share their vertex accessors. A character without a Layout (an OBJ rig)
is one mesh with one primitive per material. Attributes: POSITION (with
min/max), NORMAL (the character's own ``normals`` where it has them, else
area-weighted from the triangles, since a glTF without them is drawn flat),
TEXCOORD_0 (with a Look), COLOR_0 (the vertex colours, when not all white; an
OBJ rig's thin layers' fade as alpha), JOINTS_0 and WEIGHTS_0 (with a
Skeleton, on a skinned mesh).

Morph targets: per mesh, one target for each shape that moves a vertex of
that mesh (POSITION and NORMAL deltas), named in ``mesh.extras.targetNames``;
every primitive of the mesh has the same targets (zero where the shape does
not move its vertices). A target that moves few of a primitive's vertices is
a sparse accessor, one that moves none an accessor without a buffer view
(zeros, as the spec says). A shape that moves nothing at all is kept as a
zero target of the first mesh so its name survives. The mesh's default
weights go back from ``settings.source.default_weights``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.offline.io.gltf.names import UniqueNames
from facepuppet.offline.io.gltf.write_buffer import ELEMENT_ARRAY_BUFFER
from facepuppet.offline.io.gltf.write_state import ExportError, WriteState

_SPARSE_FRACTION = 0.5  # a target is sparse when its sparse form is under half the dense one


def plan_meshes(w: WriteState) -> None:
    """``w.primitives``: (first vertex, n vertices, triangles (k, 3) global, mesh, material) per primitive, from
    the character's Layout, else one mesh with a primitive per material; ``w.mesh_names`` and the names of the
    nodes that would hold them (``w.host_names``, unique beside the skeleton's)."""
    c = w.c
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
    w.mesh_names = mesh_names
    unique = UniqueNames(c.skeleton.names if c.skeleton is not None else ())  # a host node is not named as a joint
    w.host_names = [unique.take(name) for name in mesh_names]
    w.primitives = out


def write_meshes(w: WriteState) -> list[dict]:
    """The glTF meshes of the planned primitives (see the module doc), their accessors in the buffer; sets
    ``w.targets`` and ``w.target_index``."""
    c = w.c
    n_meshes = len(w.mesh_names)
    by_mesh: list[list[tuple]] = [[] for _ in range(n_meshes)]
    for p in w.primitives:
        by_mesh[p[3]].append(p)
    group_of = np.full(c.n_vertices, -1, np.int64)
    mesh_of_group: list[int] = []
    groups: dict[tuple[int, int], int] = {}
    for first, n, _, mesh, _ in w.primitives:
        if (first, n) not in groups:
            groups[(first, n)] = len(groups)
            mesh_of_group.append(mesh)
            group_of[first:first + n] = groups[(first, n)]
    # shapes per mesh: those with a delta on one of its vertices, in shape order
    w.targets: list[list[int]] = [[] for _ in range(n_meshes)]
    mog = np.asarray(mesh_of_group + [-1])
    orphan = []
    for s in range(c.n_shapes):
        sl = c.shape_slice(s)
        g = group_of[c.delta_indices[sl]]
        meshes = np.unique(mog[g[g >= 0]]) if len(g) else np.zeros(0, np.int64)
        if not len(meshes):
            orphan.append(s)
        for m in meshes.tolist():
            w.targets[m].append(s)
    if orphan and n_meshes:
        first_mesh = next((m for m in range(n_meshes) if by_mesh[m]), 0)
        w.targets[first_mesh] = sorted(w.targets[first_mesh] + orphan)
    w.target_index = [{s: k for k, s in enumerate(t)} for t in w.targets]
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
                shared[key] = _vertex_accessors(w, first, n, w.targets[m], skinned=not w.rigid[m])
            attrs, targets = shared[key]
            local = np.asarray(tri, dtype=np.int64) - first
            if len(local) and (local.min() < 0 or local.max() >= n):
                raise ExportError(f"layout: a triangle of mesh {w.mesh_names[m]!r} uses a vertex outside "
                                  f"its primitive's range {first}..{first + n - 1}")
            prim: dict[str, Any] = {"attributes": dict(attrs), "mode": 4, "material": int(mat)}
            if len(local):
                itype = np.uint16 if n <= 65535 else np.uint32
                prim["indices"] = w.buf.accessor(local.astype(itype).reshape(-1), ELEMENT_ARRAY_BUFFER)
            if targets:
                prim["targets"] = [dict(t) for t in targets]
            prims.append(prim)
            done += 1
            if w.progress is not None:
                w.progress(done, total, w.mesh_names[m])
        if not prims:
            continue
        mesh: dict[str, Any] = {"name": w.mesh_names[m], "primitives": prims}
        if w.targets[m]:
            names = [c.shape_names[s] for s in w.targets[m]]
            mesh["extras"] = {"targetNames": names}
            if isinstance(defaults, dict) and any(defaults.get(n) for n in names):
                mesh["weights"] = [float(defaults.get(n, 0.0)) for n in names]
        meshes.append(mesh)
    if len(meshes) != n_meshes:
        raise ExportError("layout: a mesh without primitives; every Layout mesh needs at least one")
    return meshes


def _vertex_accessors(w: WriteState, first: int, n: int, shapes: list[int],
                      skinned: bool = True) -> tuple[dict, list[dict]]:
    c, buf = w.c, w.buf
    sl = slice(first, first + n)
    attrs = {"POSITION": buf.accessor(w.vertices[sl], minmax=True), "NORMAL": buf.accessor(w.normals[sl])}
    if c.look is not None:
        attrs["TEXCOORD_0"] = buf.accessor(np.asarray(c.look.uv[sl], np.float32))
    colour = np.asarray(c.vertex_color[sl], np.float32)
    if c.look is None and w.opacity is not None:  # RGBA: the thin layers' fade in alpha
        colour = np.c_[colour, w.opacity[sl]]
    if c.look is None or not np.allclose(colour, 1.0, atol=1e-6):
        attrs["COLOR_0"] = buf.accessor(np.clip(colour, 0.0, 1.0))
    if c.skeleton is not None and skinned:
        k = c.skeleton
        joint_of = np.zeros(k.n_nodes, np.int64)
        joint_of[w.joints] = np.arange(len(w.joints))
        wt = np.asarray(k.vertex_weights[sl], np.float64)
        wt = np.where(wt > 0, wt, 0.0)
        wt /= np.maximum(wt.sum(axis=1, keepdims=True), 1e-30)
        j = np.where(wt > 0, joint_of[k.vertex_nodes[sl].astype(np.int64)], 0)
        jtype = np.uint8 if len(w.joints) <= 256 else np.uint16
        attrs["JOINTS_0"] = buf.accessor(j.astype(jtype))
        attrs["WEIGHTS_0"] = buf.accessor(wt.astype(np.float32))
    targets = []
    for s in shapes:
        ss = c.shape_slice(s)
        idx = c.delta_indices[ss].astype(np.int64)
        inside = (idx >= first) & (idx < first + n)
        local = idx[inside] - first
        order = np.argsort(local, kind="stable")
        local = local[order]
        dp = w.delta_pos[ss][inside][order]
        dn = w.delta_nrm[ss][inside][order]
        if len(local) * 16 < _SPARSE_FRACTION * n * 12:
            t = {"POSITION": buf.sparse_vec3(n, local, dp), "NORMAL": buf.sparse_vec3(n, local, dn)}
            w.summary.n_sparse_targets += 1
        else:
            dense_p = np.zeros((n, 3), np.float32)
            dense_n = np.zeros((n, 3), np.float32)
            dense_p[local], dense_n[local] = dp, dn
            t = {"POSITION": buf.accessor(dense_p, minmax=True), "NORMAL": buf.accessor(dense_n)}
        targets.append(t)
        w.summary.n_targets += 1
    return attrs, targets
