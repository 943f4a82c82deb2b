"""The scene's nodes: the default scene's roots, the hierarchy renumbered parents first, rest matrices.

The default scene is ``scene``, else scene 0, else every root node. Nodes are
stored depth first from the roots, so a parent always comes before its
children (what :class:`~facepuppet.runtime.model.character_parts.Skeleton` asks); a
node outside the default scene is not stored. The walk is a loop over an
explicit stack, so a deep hierarchy costs no recursion (its depth was bounded
before, by :mod:`.structure_limits`). Names are made unique with
``#2``, ``#3`` … A VRM 0.x avatar faces −Z: its roots are turned 180° about
+Y, so every world transform becomes ``T·G``.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.geometry import quat_to_matrix

from facepuppet.offline.io.gltf.names import UniqueNames
from facepuppet.offline.io.gltf.read_state import ReadState

TURN_Y180 = np.diag([-1.0, 1.0, -1.0, 1.0])


def read_nodes(state: ReadState) -> None:
    """Fill ``node_from_file``, ``stored_of``, ``parent``, ``rest_local``, ``world`` and ``node_names``."""
    f = state.f
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
    roots = _scene_roots(state, parent_of)
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
    state.node_from_file = np.array(order, dtype=np.int64)
    state.stored_of = {file_i: s for s, file_i in enumerate(order)}
    state.parent = np.array([state.stored_of.get(int(parent_of[i]), -1) for i in order], dtype=np.int64)
    local = np.array([_local(state, i, nodes[i]) for i in order]).reshape(-1, 4, 4)
    if state.turn:
        local[state.parent < 0] = TURN_Y180 @ local[state.parent < 0]
    state.rest_local = local
    world = np.empty_like(local)
    for s in range(len(order)):
        p = int(state.parent[s])
        world[s] = local[s] if p < 0 else world[p] @ local[s]
    if not np.isfinite(world).all():
        f.fail("nodes", "the node transforms overflow (non-finite world matrices)")
    state.world = world  # stored frame (turned for VRM 0.x)
    unique = UniqueNames()
    state.node_names = [unique.take(nodes[i].get("name") if isinstance(nodes[i].get("name"), str) and nodes[i]["name"]
                                    else f"node{i}") for i in order]


def _scene_roots(state: ReadState, parent_of: np.ndarray) -> list[int]:
    f = state.f
    scenes = f.items("scenes")
    if scenes:
        s = f.get(state.doc, "scene", int, "", 0)
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


def _local(state: ReadState, i: int, node: dict) -> np.ndarray:
    f, w = state.f, f"nodes[{i}]"
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
