"""A character's spring bones as arrays: the joints, their chains and the colliders (``settings["springs"]``).

The importer (``import-rig`` of a VRM) writes the springs into the character
table's settings as plain JSON, one form for VRM 0.x and 1.0::

    {"chains": [{"name", "center": node or -1, "colliders": [collider, ...],
                 "joints": [{"node", "tail_node": node or -1 (a virtual tail), "tail": [x, y, z] in the node's frame,
                             "stiffness", "drag", "gravity_power", "gravity_dir": [x, y, z], "hit_radius"}]}],
     "colliders": [{"node", "shape": "sphere" | "capsule", "offset": [x, y, z], "tail": [x, y, z], "radius"}]}

:func:`spring_rig` checks it (the table is read from a file, so every field is
checked as input: types, finiteness, ranges, node indices, sizes) and returns
a :class:`SpringRig`, the arrays the simulation
(:mod:`facepuppet.runtime.render.spring_bones`) runs on. Joints come out
ordered parents first (the stored nodes are), so one pass in that order sees
every joint's parent already moved.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.files.tables import TablesError

if TYPE_CHECKING:  # for the hint only: character.py imports this module to check its table (a cycle)
    from facepuppet.runtime.model.character import Character

#: Bounds on what a table may ask of the simulation (the importer's own bounds are the same).
MAX_JOINTS = 4096
MAX_COLLIDERS = 1024
MAX_CHAINS = 1024
SHAPES = {"sphere": 0, "capsule": 1}
_W = "settings.springs"


@dataclass(frozen=True, eq=False)
class SpringRig:
    """The spring joints and colliders of a character, arrays ordered parents first.

    Attributes
    ----------
    node : ndarray (n_joints,) int64, the node each joint turns
    tail_node : ndarray (n_joints,) int64, the node at its tail, -1 for a virtual tail
    tail : ndarray (n_joints, 3) float64, the tail's rest position in the joint node's frame
    stiffness, drag, gravity_power, hit_radius : ndarray (n_joints,) float64
    gravity_dir : ndarray (n_joints, 3) float64, character frame
    center : ndarray (n_joints,) int64, the chain's center node, -1 for the character's space
    chain : ndarray (n_joints,) int64, the chain of each joint
    chain_names : tuple of n_chains str
    collider_node : ndarray (n_colliders,) int64
    collider_shape : ndarray (n_colliders,) int64, :data:`SHAPES`
    collider_offset, collider_tail : ndarray (n_colliders, 3) float64, in the collider node's frame
    collider_radius : ndarray (n_colliders,) float64
    hits : ndarray (n_joints, n_colliders) bool, the colliders each joint collides with
    """

    node: np.ndarray
    tail_node: np.ndarray
    tail: np.ndarray
    stiffness: np.ndarray
    drag: np.ndarray
    gravity_power: np.ndarray
    gravity_dir: np.ndarray
    hit_radius: np.ndarray
    center: np.ndarray
    chain: np.ndarray
    chain_names: tuple[str, ...]
    collider_node: np.ndarray
    collider_shape: np.ndarray
    collider_offset: np.ndarray
    collider_tail: np.ndarray
    collider_radius: np.ndarray
    hits: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.node)

    @property
    def n_colliders(self) -> int:
        return len(self.collider_node)

    def describe(self, node_names: tuple[str, ...] | None = None) -> list[str]:
        """One line per chain (joints, settings, colliders) and one for the colliders: what import-rig prints."""
        def name(n: int) -> str:
            return node_names[n] if node_names is not None and 0 <= n < len(node_names) else str(n)

        lines = []
        for c, chain_name in enumerate(self.chain_names):
            j = np.flatnonzero(self.chain == c)
            joints = " → ".join(name(int(self.node[i])) + ("" if self.tail_node[i] >= 0 else " (+7 cm tail)")
                                for i in j)
            k = int(j[0])
            cols = int(self.hits[k].sum())
            center = "" if self.center[k] < 0 else f", center {name(int(self.center[k]))}"
            lines.append(f"spring {chain_name}: {len(j)} joints {joints}; stiffness {self.stiffness[k]:g}, "
                         f"drag {self.drag[k]:g}, gravity {self.gravity_power[k]:g}, hit radius "
                         f"{self.hit_radius[k]:g}, {cols} colliders{center}")
        shapes = {v: k for k, v in SHAPES.items()}
        for i in range(self.n_colliders):
            lines.append(f"collider {i}: {shapes[int(self.collider_shape[i])]} r {self.collider_radius[i]:g} on "
                         f"{name(int(self.collider_node[i]))}")
        return lines


def _fail(where: str, problem: str):
    raise TablesError(None, where, problem)


def _list(value: Any, where: str, limit: int) -> list:
    if not isinstance(value, list):
        _fail(where, f"expected an array, found {type(value).__name__}")
    if len(value) > limit:
        _fail(where, f"{len(value)} entries; at most {limit}")
    return value


def _number(o: Mapping, key: str, where: str, lo: float = -np.inf, hi: float = np.inf) -> float:
    v = o.get(key)
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or not lo <= v <= hi:
        _fail(f"{where}.{key}", f"expected a finite number in [{lo}, {hi}], found {v!r}")
    return float(v)


def _vec(o: Mapping, key: str, where: str) -> list[float]:
    v = o.get(key)
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and np.isfinite(x) for x in v)):
        _fail(f"{where}.{key}", f"expected 3 finite numbers, found {v!r}")
    return [float(x) for x in v]


def _node(o: Mapping, key: str, where: str, n_nodes: int, allow_none: bool = False) -> int:
    v = o.get(key)
    lo = -1 if allow_none else 0
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v < n_nodes:
        _fail(f"{where}.{key}", f"expected a node index in [{lo}, {n_nodes - 1}], found {v!r}")
    return int(v)


def _obj(v: Any, where: str) -> Mapping:
    if not isinstance(v, Mapping):
        _fail(where, f"expected an object, found {type(v).__name__}")
    return v


def spring_rig(springs: Any, parent: np.ndarray, rest_world: np.ndarray | None = None) -> SpringRig | None:
    """The checked :class:`SpringRig` of a character's ``settings["springs"]`` (None when it has none).

    Parameters
    ----------
    springs : the JSON value (None: no springs)
    parent : ndarray (n_nodes,) int, the skeleton's parents (node indices are checked against it, and each
        joint's tail node must lie below its joint)
    rest_world : ndarray (n_nodes, 4, 4), the skeleton's rest world transforms, or None: when given, the
        joints, their parents and the colliders' and centers' nodes must have invertible ones (the simulation
        works in their frames)

    Raises
    ------
    TablesError naming ``settings.springs...``, the field and what was found.
    """
    if springs is None:
        return None
    springs = _obj(springs, _W)
    n_nodes = len(parent)
    colliders = _list(springs.get("colliders", []), f"{_W}.colliders", MAX_COLLIDERS)
    c_node, c_shape, c_off, c_tail, c_r = [], [], [], [], []
    for i, c in enumerate(colliders):
        w = f"{_W}.colliders[{i}]"
        c = _obj(c, w)
        c_node.append(_node(c, "node", w, n_nodes))
        if c.get("shape") not in SHAPES:
            _fail(f"{w}.shape", f"expected one of {sorted(SHAPES)}, found {c.get('shape')!r}")
        c_shape.append(SHAPES[c["shape"]])
        c_off.append(_vec(c, "offset", w))
        c_tail.append(_vec(c, "tail", w))
        c_r.append(_number(c, "radius", w, 0.0))
    rows: list[tuple] = []
    chains = _list(springs.get("chains", []), f"{_W}.chains", MAX_CHAINS)
    names = []
    n_joints = 0
    for k, ch in enumerate(chains):
        w = f"{_W}.chains[{k}]"
        ch = _obj(ch, w)
        names.append(str(ch.get("name", f"chain{k}")))
        center = _node(ch, "center", w, n_nodes, allow_none=True)
        refs = _list(ch.get("colliders", []), f"{w}.colliders", MAX_COLLIDERS)
        for i, r in enumerate(refs):
            if not isinstance(r, int) or isinstance(r, bool) or not 0 <= r < len(colliders):
                _fail(f"{w}.colliders[{i}]", f"{r!r} is not a collider index (0..{len(colliders) - 1})")
        joints = _list(ch.get("joints", []), f"{w}.joints", MAX_JOINTS)
        n_joints += len(joints)
        if n_joints > MAX_JOINTS:
            _fail(f"{w}.joints", f"more than {MAX_JOINTS} joints in all")
        for i, j in enumerate(joints):
            jw = f"{w}.joints[{i}]"
            j = _obj(j, jw)
            node = _node(j, "node", jw, n_nodes)
            tail_node = _node(j, "tail_node", jw, n_nodes, allow_none=True)
            if tail_node >= 0 and not _below(parent, tail_node, node):
                _fail(f"{jw}.tail_node", f"node {tail_node} is not below the joint's node {node}")
            tail = _vec(j, "tail", jw)
            if np.linalg.norm(tail) < 1e-9:
                _fail(f"{jw}.tail", "the tail sits on the joint (a bone needs a length)")
            rows.append((node, tail_node, tail, _number(j, "stiffness", jw, 0.0), _number(j, "drag", jw, 0.0, 1.0),
                         _number(j, "gravity_power", jw, 0.0), _vec(j, "gravity_dir", jw),
                         _number(j, "hit_radius", jw, 0.0), center, k, refs, jw))
    rows.sort(key=lambda r: r[0])  # stored nodes are parents first
    for a, b in zip(rows, rows[1:]):
        if a[0] == b[0]:
            _fail(f"{b[-1]}.node", f"node {b[0]} is simulated twice")
    if rest_world is not None:
        used = [(r[0], f"{r[-1]}.node") for r in rows] + [(int(parent[r[0]]), f"{r[-1]}.node") for r in rows]
        used += [(n, f"{_W}.colliders[{i}].node") for i, n in enumerate(c_node)]
        used += [(r[8], f"{r[-1]}.center") for r in rows]
        for n, where in used:
            if n >= 0 and not abs(np.linalg.det(rest_world[n][:3, :3])) > 1e-12:
                _fail(where, f"node {n} has a singular rest transform (a zero scale): no frame to simulate in")
    hits = np.zeros((len(rows), len(colliders)), bool)
    for i, r in enumerate(rows):
        hits[i, r[10]] = True
    col = list(zip(*rows)) if rows else [[]] * 12
    return SpringRig(
        node=np.array(col[0], np.int64), tail_node=np.array(col[1], np.int64),
        tail=np.array(col[2], np.float64).reshape(-1, 3), stiffness=np.array(col[3], np.float64),
        drag=np.array(col[4], np.float64), gravity_power=np.array(col[5], np.float64),
        gravity_dir=np.array(col[6], np.float64).reshape(-1, 3), hit_radius=np.array(col[7], np.float64),
        center=np.array(col[8], np.int64), chain=np.array(col[9], np.int64), chain_names=tuple(names),
        collider_node=np.array(c_node, np.int64), collider_shape=np.array(c_shape, np.int64),
        collider_offset=np.array(c_off, np.float64).reshape(-1, 3),
        collider_tail=np.array(c_tail, np.float64).reshape(-1, 3), collider_radius=np.array(c_r, np.float64),
        hits=hits)


def _below(parent: np.ndarray, node: int, ancestor: int) -> bool:
    while node >= 0:
        node = int(parent[node])
        if node == ancestor:
            return True
    return False


def springs_of(character: Character) -> SpringRig | None:
    """The character's springs (None without a skeleton or springs); checked as :func:`spring_rig` says."""
    if character.skeleton is None:
        return None
    springs = character.metadata.get("settings", {}).get("springs")
    if springs is None:
        return None
    return spring_rig(springs, character.skeleton.parent, character.skeleton.global_transforms())
