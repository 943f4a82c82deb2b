"""Where a character's spring joints sit, arranged once for the simulation's per-step arithmetic.

:class:`SpringLayout` holds what :mod:`facepuppet.runtime.render.spring_bones`
reads every step and never changes: the joints in *level* order (a joint's
level is one more than the nearest joint above it, so each level is a
contiguous run processed at once, after the levels above it), what each
joint's frame hangs from (its *anchor*: a driver node, whose pose comes from
the head pose alone, or a joint of an earlier level) and its rest frame
relative to that anchor, the drivers (the anchors' nodes, the colliders' and
centers' nodes), and the nodes below the joints that follow them.

Rows of the simulation's world transforms ``W`` (one array): 0 the identity
(the world, for chains without a center), 1 the model matrix, then one per
driver node, then one per joint in level order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.model.character_parts import Skeleton
from facepuppet.runtime.model.springs import SpringRig

#: ``W``'s first rows: the world (identity) and the model matrix.
WORLD_ROW, MODEL_ROW = 0, 1


@dataclass(frozen=True, eq=False)
class SpringLayout:
    """The joints of a :class:`~facepuppet.runtime.model.springs.SpringRig` in level order.

    Attributes
    ----------
    order : ndarray (n,) int64, the rig's joint at each position of the level order
    levels : tuple of (start, stop), the positions of each level, top level first
    node : ndarray (n,) int64, each joint's node
    driver_nodes : ndarray (nd,) int64, the driver nodes (their rows are 2 + their index)
    g_drivers : ndarray (nd, 4, 4) float64, their rest world transforms
    anchor : ndarray (n,) int64, the ``W`` row each joint's frame hangs from
    rel_local : ndarray (n, 4, 4) float64, the joint's rest frame in its anchor's frame
    g_inv : ndarray (n, 4, 4) float64, the inverse of each joint's rest world transform
    center_row : ndarray (n,) int64, the ``W`` row of each joint's center (``WORLD_ROW``: none)
    collider_row : ndarray (n_colliders,) int64
    axis : ndarray (n, 3), the unit rest direction of each joint's tail in its frame
    length : ndarray (n,), the bone lengths in world units
    inertia : ndarray (n, 3), 1 - drag (repeated per axis: an in-place product without broadcasting)
    push : ndarray (n, 1), stiffness · step
    gravity : ndarray (n, 3), gravity direction · power · step
    hits : ndarray (n, n_colliders) bool; reach : ndarray (n, n_colliders), collider radius + hit radius
    follow_nodes, follow_joint : ndarray (m,) int64, nodes below a joint that are not joints and the position
        of the joint they follow
    moved_nodes : ndarray (n_nodes,) bool, the joints and their followers
    """

    order: np.ndarray
    levels: tuple[tuple[int, int], ...]
    node: np.ndarray
    driver_nodes: np.ndarray
    g_drivers: np.ndarray
    anchor: np.ndarray
    rel_local: np.ndarray
    g_inv: np.ndarray
    center_row: np.ndarray
    collider_row: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    inertia: np.ndarray
    push: np.ndarray
    gravity: np.ndarray
    hits: np.ndarray
    reach: np.ndarray
    follow_nodes: np.ndarray
    follow_joint: np.ndarray
    moved_nodes: np.ndarray

    @property
    def n_rows(self) -> int:
        """Rows of ``W``: the world, the model, the drivers, the joints."""
        return 2 + len(self.driver_nodes) + len(self.node)


def spring_layout(rig: SpringRig, skeleton: Skeleton, step_s: float) -> SpringLayout:
    """Arrange ``rig``'s joints over ``skeleton`` for steps of ``step_s`` seconds (see the module doc)."""
    n, n_nodes = rig.n_joints, skeleton.n_nodes
    g = skeleton.global_transforms()
    parent = skeleton.parent.astype(np.int64)
    joint_of = np.full(n_nodes, -1, np.int64)
    joint_of[rig.node] = np.arange(n)
    above = np.full(n_nodes, -1, np.int64)  # the nearest joint node above each node (itself excluded)
    for s in range(n_nodes):
        p = int(parent[s])
        if p >= 0:
            above[s] = p if joint_of[p] >= 0 else above[p]
    level = np.zeros(n, np.int64)
    for j in range(n):  # the rig is parents first
        a = above[rig.node[j]]
        level[j] = 0 if a < 0 else level[joint_of[a]] + 1
    order = np.argsort(level, kind="stable")
    position = np.empty(n, np.int64)
    position[order] = np.arange(n)
    levels = tuple((int(np.searchsorted(level[order], v)), int(np.searchsorted(level[order], v, side="right")))
                   for v in range(int(level.max()) + 1 if n else 0))
    drivers: list[int] = []
    for j in range(n):
        if above[rig.node[j]] < 0 and parent[rig.node[j]] >= 0:
            drivers.append(int(parent[rig.node[j]]))
    drivers += [int(x) for x in rig.collider_node] + [int(x) for x in rig.center if x >= 0]
    driver_nodes = np.array(list(dict.fromkeys(drivers)), np.int64)
    row = {int(d): 2 + i for i, d in enumerate(driver_nodes)}
    first_joint_row = 2 + len(driver_nodes)
    anchor = np.empty(n, np.int64)
    rel_local = np.empty((n, 4, 4))
    for i, j in enumerate(order):
        node, p = int(rig.node[j]), int(parent[rig.node[j]])
        if above[node] >= 0:
            anchor[i] = first_joint_row + position[joint_of[above[node]]]
            rel_local[i] = np.linalg.solve(g[above[node]], g[node])
        elif p >= 0:
            anchor[i], rel_local[i] = row[p], np.linalg.solve(g[p], g[node])
        else:  # a root joint hangs from the model matrix
            anchor[i], rel_local[i] = MODEL_ROW, g[node]
    tail = rig.tail[order]
    rest_length = np.linalg.norm(tail, axis=1)
    scale = np.linalg.norm(g[rig.node[order]][:, :3, 0], axis=1) if n else np.zeros(0)
    follow = [(s, int(position[joint_of[above[s]]])) for s in range(n_nodes) if joint_of[s] < 0 and above[s] >= 0]
    moved = np.zeros(n_nodes, bool)
    moved[rig.node] = True
    moved[[s for s, _ in follow]] = True
    hits = rig.hits[order]
    return SpringLayout(
        order=order, levels=levels, node=rig.node[order], driver_nodes=driver_nodes,
        g_drivers=g[driver_nodes] if len(driver_nodes) else np.zeros((0, 4, 4)), anchor=anchor,
        rel_local=rel_local, g_inv=np.linalg.inv(g[rig.node[order]]) if n else np.zeros((0, 4, 4)),
        center_row=np.array([row[int(c)] if c >= 0 else WORLD_ROW for c in rig.center[order]], np.int64),
        collider_row=np.array([row[int(c)] for c in rig.collider_node], np.int64),
        axis=tail / np.maximum(rest_length, 1e-12)[:, None], length=rest_length * scale,
        inertia=np.repeat((1.0 - rig.drag[order])[:, None], 3, axis=1), push=(rig.stiffness[order] * step_s)[:, None],
        gravity=rig.gravity_dir[order] * (rig.gravity_power[order] * step_s)[:, None],
        hits=hits, reach=rig.collider_radius[None, :] + rig.hit_radius[order][:, None],
        follow_nodes=np.array([s for s, _ in follow], np.int64),
        follow_joint=np.array([j for _, j in follow], np.int64), moved_nodes=moved)
