"""The written scene's nodes: the skeleton's hierarchy, the nodes holding the meshes, the skin.

The skeleton's nodes go out parents first (the stored order) with their
local rest matrices as translation/rotation/scale when they decompose
without shear, else as ``matrix``. One skin's joints are the nodes any vertex
follows with a non-zero weight; its inverse bind matrices are the inverse of
each joint's rest world transform (vertices are stored in the world rest
pose, so at rest every joint matrix is the identity). Each mesh goes back on
the node that held it in the file when the reader kept it
(``settings.source.mesh_nodes``), else on a new root node of its own. For a
VRM 0.x the roots carry the turn 180° about +Y, so every world transform
becomes ``T·G`` (the inverse of the reader's turn).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from facepuppet.runtime.model.geometry import matrix_to_quat

from facepuppet.offline.io.gltf.write_state import WriteState

TURN_Y180 = np.diag([-1.0, 1.0, -1.0, 1.0])


def write_nodes(w: WriteState) -> list[dict]:
    """The skeleton's nodes, parents first as stored, with their local rest transforms (scaled to metres,
    the roots turned for a VRM 0.x); also finds the skin's joints."""
    k = w.c.skeleton
    w.n_skeleton_nodes = 0 if k is None else k.n_nodes
    if k is None:
        return []
    weights = k.vertex_weights
    w.joints = np.unique(k.vertex_nodes[weights > 0]).astype(np.int64)
    if not len(w.joints):
        w.joints = np.zeros(1, np.int64)
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
    """Put each mesh on a node (in place in ``nodes``; ``w.host``): back on the node that held it in the file
    when the reader kept it, else on a new root node named after it; with a skeleton, that node carries the
    skin (a skinned mesh's node transform is ignored)."""
    kept = _mesh_nodes(w, n_meshes)
    w.host = []
    for m in range(n_meshes):
        if kept is not None:  # back on the node that held it in the file
            node = nodes[kept[m]]
            node["mesh"] = m
        else:
            node = {"name": w.host_names[m], "mesh": m}
            nodes.append(node)
        if w.c.skeleton is not None:
            node["skin"] = 0
        w.host.append(kept[m] if kept is not None else len(nodes) - 1)


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

