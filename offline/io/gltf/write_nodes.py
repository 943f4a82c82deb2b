"""The written scene's nodes: the skeleton's hierarchy, the nodes holding the meshes, the skin.

The skeleton's nodes go out parents first (the stored order) with their
local rest matrices as translation/rotation/scale when they decompose
without shear, else as ``matrix``. Each mesh goes back on the node that held
it in the file when the reader kept it (``settings.source.mesh_nodes``), else
on a new root node of its own. A mesh whose every vertex follows only its
own node (an unskinned mesh in the file: the reader made it follow its node)
goes back unskinned, its vertices in that node's frame (:func:`rigid_frames`),
so that no node is skinned to itself. The other meshes share one skin: its
joints are the nodes their vertices follow with a non-zero weight, its
inverse bind matrices the inverse of each joint's rest world transform
(vertices are stored in the world rest pose, so at rest every joint matrix is
the identity); a skinned mesh's node carries no transform (the spec ignores
it), and one that needs its transform (a joint, a parent, not a root) holds
no mesh: the mesh goes on a new root node. For a VRM 0.x the roots carry the
turn 180° about +Y, so every world transform becomes ``T·G`` (the inverse of
the reader's turn).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.runtime.model.geometry import matrix_to_quat

from facepuppet.offline.io.gltf.write_state import WriteState

TURN_Y180 = np.diag([-1.0, 1.0, -1.0, 1.0])


def write_nodes(w: WriteState) -> list[dict]:
    """The skeleton's nodes, parents first as stored, with their local rest transforms (scaled to metres,
    the roots turned for a VRM 0.x)."""
    k = w.c.skeleton
    w.n_skeleton_nodes = 0 if k is None else k.n_nodes
    if k is None:
        return []
    t = TURN_Y180 if w.turn else np.eye(4)
    nodes = []
    children: list[list[int]] = [[] for _ in range(k.n_nodes)]
    for j in range(k.n_nodes):
        if k.parent[j] >= 0:
            children[int(k.parent[j])].append(j)
    for j in range(k.n_nodes):
        local = np.asarray(k.rest_local[j], dtype=np.float64).copy()
        local[:3, 3] *= w.scale
        if k.parent[j] < 0:  # turning the whole scene: the roots carry the turn, children are unchanged
            local = t @ local
        node: dict[str, Any] = {"name": k.names[j], **_trs(local)}
        if children[j]:
            node["children"] = children[j]
        nodes.append(node)
    return nodes


def _mesh_nodes(w: WriteState, n_meshes: int) -> list[int] | None:
    """``settings.source.mesh_nodes``: the stored node that held each Layout mesh in the file, when the
    reader kept it and it is usable (one distinct skeleton node per mesh); None: each mesh gets a new
    root node."""
    hint = w.c.source.get("mesh_nodes")
    if hint is None or w.c.skeleton is None:
        return None
    ok = (isinstance(hint, list) and len(hint) == n_meshes and len(set(map(str, hint))) == n_meshes
          and all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n < w.n_skeleton_nodes
                  for n in hint))
    if not ok:
        w.warn(f"settings.source.mesh_nodes {hint!r} is not one distinct node per mesh "
               f"({n_meshes} meshes, {w.n_skeleton_nodes} nodes): each mesh gets a node of its own")
        return None
    return [int(n) for n in hint]


def plan_hosts(w: WriteState) -> None:
    """Which node holds each planned mesh (``w.host``, -1: a new root node) and which meshes are rigid
    (``w.rigid``: every vertex follows only that node, written unskinned); the skin's joints
    (``w.joints``): the nodes the skinned meshes' vertices follow."""
    n_meshes = len(w.mesh_names)
    kept = _mesh_nodes(w, n_meshes)
    w.host = list(kept) if kept is not None else [-1] * n_meshes
    w.rigid = [False] * n_meshes
    k = w.c.skeleton
    if k is None:
        return
    ranges: list[list[tuple[int, int]]] = [[] for _ in range(n_meshes)]
    for first, n, _, mesh, _ in w.primitives:
        ranges[mesh].append((first, n))
    skinned_nodes: list[np.ndarray] = []
    for m in range(n_meshes):
        sel = np.concatenate([np.arange(f, f + n) for f, n in ranges[m]]) if ranges[m] else np.zeros(0, np.int64)
        nodes, weights = k.vertex_nodes[sel].astype(np.int64), k.vertex_weights[sel]
        followed = np.unique(nodes[weights > 0])
        if w.host[m] >= 0 and len(sel) and followed.tolist() == [w.host[m]]:
            w.rigid[m] = True
        else:
            skinned_nodes.append(followed)
    w.joints = np.unique(np.concatenate(skinned_nodes)).astype(np.int64) if skinned_nodes else None
    if w.joints is not None and not len(w.joints):
        w.joints = np.zeros(1, np.int64)


def rigid_frames(w: WriteState) -> None:
    """The rigid meshes' vertices, normals and morph deltas into their node's frame (``w.vertices`` … in place):
    points by the inverse of the node's world rest transform in the file, normals by its transpose's inverse."""
    k = w.c.skeleton
    if k is None or not any(w.rigid):
        return
    t = TURN_Y180 if w.turn else np.eye(4)
    world = k.global_transforms().astype(np.float64)
    world[:, :3, 3] *= w.scale
    c = w.c
    vertex_mesh = np.full(c.n_vertices, -1, np.int64)
    for first, n, _, mesh, _ in w.primitives:
        vertex_mesh[first:first + n] = mesh
    delta_mesh = vertex_mesh[c.delta_indices.astype(np.int64)] if len(c.delta_indices) else np.zeros(0, np.int64)
    for m, rigid in enumerate(w.rigid):
        if not rigid:
            continue
        inv = np.linalg.inv(t @ world[w.host[m]])
        lin, shift = inv[:3, :3], inv[:3, 3]
        normal_lin = np.linalg.inv(lin).T
        sel = vertex_mesh == m
        w.vertices[sel] = (w.vertices[sel].astype(np.float64) @ lin.T + shift).astype(np.float32)
        nrm = w.normals[sel].astype(np.float64) @ normal_lin.T
        w.normals[sel] = (nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)).astype(np.float32)
        ds = delta_mesh == m
        w.delta_pos[ds] = (w.delta_pos[ds].astype(np.float64) @ lin.T).astype(np.float32)
        w.delta_nrm[ds] = (w.delta_nrm[ds].astype(np.float64) @ normal_lin.T).astype(np.float32)


def write_skin(w: WriteState) -> dict:
    """The one skin: the joints any vertex follows, their inverse bind matrices (the inverse of each joint's
    rest world transform, turned and scaled as the nodes)."""
    k = w.c.skeleton
    t = TURN_Y180 if w.turn else np.eye(4)
    world = k.global_transforms()
    world[:, :3, 3] *= w.scale
    joints = w.joints
    ibm = np.stack([np.linalg.inv(t @ world[j]) for j in joints])
    ibm[:, 3] = (0, 0, 0, 1)  # exact affine bottom row
    cols = np.ascontiguousarray(np.transpose(ibm, (0, 2, 1)), dtype=np.float32).reshape(len(joints), 16)
    acc = w.buf.accessor(cols, target=None)
    w.summary.n_joints = len(joints)
    return {"joints": [int(j) for j in joints], "inverseBindMatrices": acc}


def place_meshes(w: WriteState, nodes: list[dict], n_meshes: int) -> None:
    """Put each mesh on a node (in place in ``nodes``; ``w.host`` becomes the written node): a rigid mesh on its
    own node, unskinned; a skinned one back on the node that held it in the file when that node's transform
    can go (a root that is no joint and no parent: the spec ignores a skinned mesh's node transform), else on a
    new root node named after it (also when it is a humanoid bone); every skinned mesh's node carries the
    skin."""
    k = w.c.skeleton
    needed = set(w.joints.tolist()) if w.joints is not None else set()
    if k is not None:
        needed |= {int(p) for p in k.parent if p >= 0} | {j for j in range(k.n_nodes) if k.parent[j] >= 0}
        needed |= {int(j) for j in k.bones.values()}
    for m in range(n_meshes):
        h = w.host[m]
        if h >= 0 and (w.rigid[m] or h not in needed):
            node = nodes[h]
            if not w.rigid[m]:  # skinned: its node's transform is ignored by the spec, so it carries none
                for key in ("translation", "rotation", "scale", "matrix"):
                    node.pop(key, None)
        else:
            node = {"name": w.host_names[m]}
            nodes.append(node)
            w.host[m] = len(nodes) - 1
        node["mesh"] = m
        if not w.rigid[m] and k is not None:
            node["skin"] = 0


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

