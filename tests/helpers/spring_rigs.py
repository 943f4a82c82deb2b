"""Small skeletons with spring chains, built in code, for the spring bone simulation's tests.

A root node at the origin, a ``head`` node 1.5 m up, and a chain of joints
hanging from the head along a given direction. The springs are written in the
table's JSON form (``settings["springs"]``) and read through
:func:`~facepuppet.runtime.model.springs.spring_rig`, as a loaded character's are.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character_parts import Skeleton
from facepuppet.runtime.model.springs import SpringRig, spring_rig

HEAD = np.array([0.0, 1.5, 0.0])


def chain_skeleton(n_links: int = 3, step=(0.1, 0.0, 0.0)) -> Skeleton:
    """root (0) → head (1) at :data:`HEAD` → link 2 → … → link n_links + 1, each ``step`` from its parent
    (the last link is the chain's tail)."""
    n = n_links + 2
    local = np.tile(np.eye(4), (n, 1, 1))
    local[1, :3, 3] = HEAD
    local[2:, :3, 3] = step
    parent = np.array([-1] + list(range(n - 1)), np.int32)
    return Skeleton(tuple(["root", "head"] + [f"link{i}" for i in range(n_links)]), parent,
                    local.astype(np.float32), np.zeros((1, 4), np.uint16),
                    np.array([[1.0, 0, 0, 0]], np.float32), {"head": 1})


def chain_springs(sk: Skeleton, *, stiffness=1.0, drag=0.4, gravity_power=0.0, gravity_dir=(0, -1, 0),
                  hit_radius=0.0, center=-1, colliders=()) -> dict:
    """The ``settings["springs"]`` JSON of one chain over links 2 .. n-2, each turning toward the next node."""
    joints = [{"node": j, "tail_node": j + 1, "tail": [float(x) for x in sk.rest_local[j + 1][:3, 3]],
               "stiffness": stiffness, "drag": drag, "gravity_power": gravity_power,
               "gravity_dir": list(gravity_dir), "hit_radius": hit_radius} for j in range(2, sk.n_nodes - 1)]
    return {"chains": [{"name": "chain", "center": center, "colliders": list(range(len(colliders))),
                        "joints": joints}],
            "colliders": list(colliders)}


def rig_of(sk: Skeleton, springs: dict) -> SpringRig:
    return spring_rig(springs, sk.parent)


def yaw_quat(angle: float) -> np.ndarray:
    return np.array([0.0, np.sin(angle / 2), 0.0, np.cos(angle / 2)])


def head_skinning(sk: Skeleton, rotation: np.ndarray | None) -> np.ndarray:
    """Skinning matrices (n_nodes, 4, 4) float32 turning the head node (and below) by ``rotation`` about its
    rest position, as the renderer's head pose does."""
    return sk.pose_matrices({1: rotation} if rotation is not None else None)
