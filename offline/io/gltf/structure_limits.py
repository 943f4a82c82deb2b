"""How big a glTF's structure may be: counts and depths checked from its JSON before anything is decoded.

A stranger's avatar is read by loops over its nodes, meshes and primitives,
and every mesh instance of the scene is stored as its own copy. A file of a
few hundred kilobytes can declare a structure whose reading would take hours
or gigabytes: 30,001 nodes, 3,000 instances of one mesh, 4,000 primitives, a
60,000-deep chain, a small mesh instanced into millions of stored vertices.
Each limit below is stated once, far above any real avatar (VRoid Studio's
have a few hundred nodes about 12 deep, under 10 meshes, under 100 primitives
and under 100k vertices; the heaviest game avatars some thousands of nodes and
a million vertices) and far below what would hurt; the reader's loops are
linear, so a file within them reads in time proportional to what it declares.

The counts of the file (nodes, meshes, primitives) and the depth of its node
hierarchy are checked first (:func:`structure_problems`, which ``check-gltf``
can list as well: it only reads the JSON, whatever types it holds); what the
default scene stores (the primitives of its mesh instances, their vertices,
triangles and morph values, from the accessors' declared counts, each instance counted,
and apart the vertices a mesh instanced again stores again) before the first
accessor is decoded. The JSON a character keeps as it came (the VRM
extension, the asset's meta) must nest no deeper than
:data:`MAX_KEPT_JSON_DEPTH` and hold finite numbers, so that its character
table can be written and read back.
Each refusal names the file and the JSON path where the limit was crossed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from facepuppet.offline.io.gltf_container import GltfFile

#: Nodes in the file (a character holds at most 65,535).
MAX_NODES = 20_000
#: Levels of the node hierarchy (a root is level 1); real skeletons with long hair chains are under 100 deep.
MAX_DEPTH = 512
#: Meshes in the file, and mesh instances (nodes with a mesh) in the file.
MAX_MESHES = 2_000
#: Primitives in the file, and primitives stored for the default scene (each instance of a mesh counts).
MAX_PRIMITIVES = 2_000
#: Vertices stored for the default scene (each instance counts), by the POSITION accessors' declared counts.
MAX_VERTICES = 4_000_000
#: Of those, the vertices stored by instances of a mesh already stored: copies of what the file holds once, so a
#: small file instancing a mesh many times costs what a file holding them all would (a few hundred copies of a
#: button are 100k).
MAX_REPEATED_VERTICES = 500_000
#: Triangles stored for the default scene (each instance counts), by the index accessors' declared counts.
MAX_TRIANGLES = 8_000_000
#: Morph values read for the default scene: vertices × morph targets, summed over what is stored.
MAX_MORPH_VALUES = 50_000_000
#: Nesting of the JSON a character keeps as it came (the table's manifest nests it 3 deep and allows 32).
MAX_KEPT_JSON_DEPTH = 24


def structure_problems(doc: Any) -> Iterator[tuple[str, str]]:
    """(JSON path, problem) of each file-level limit a glTF document ``doc`` crosses: its nodes, meshes, mesh
    instances and primitives counted, its node hierarchy's depth walked (iteratively, each node once, from the
    nodes no node lists as a child). Whatever JSON it holds, this only reads: a malformed part is skipped, for
    the reader's own checks to refuse by name. The first limit crossed ends the walk (its cost stays linear in
    the file)."""
    nodes = doc.get("nodes") if isinstance(doc, dict) else None
    nodes = nodes if isinstance(nodes, list) else []
    if len(nodes) > MAX_NODES:
        yield "nodes", f"{len(nodes)} nodes; a file may have at most {MAX_NODES}"
        return
    meshes = doc.get("meshes") if isinstance(doc, dict) else None
    meshes = meshes if isinstance(meshes, list) else []
    if len(meshes) > MAX_MESHES:
        yield "meshes", f"{len(meshes)} meshes; a file may have at most {MAX_MESHES}"
        return
    instances = 0
    for i, node in enumerate(nodes):
        if isinstance(node, dict) and "mesh" in node:
            instances += 1
            if instances > MAX_MESHES:
                yield (f"nodes[{i}].mesh", f"mesh instance {instances} (a node with a mesh); a file may have at most "
                                           f"{MAX_MESHES}, as a character holds at most {MAX_MESHES} meshes")
                return
    total = 0
    for m, mesh in enumerate(meshes):
        prims = mesh.get("primitives") if isinstance(mesh, dict) else None
        if isinstance(prims, list):
            total += len(prims)
            if total > MAX_PRIMITIVES:
                yield (f"meshes[{m}].primitives", f"{len(prims)} primitives bring the file's to {total}; a file may "
                                                  f"have at most {MAX_PRIMITIVES}")
                return
    problem = _too_deep(nodes)
    if problem is not None:
        yield problem


def _too_deep(nodes: list) -> tuple[str, str] | None:
    """The first node (depth first from the roots) past :data:`MAX_DEPTH`, as (path, problem), or None."""
    n = len(nodes)
    children = [[c for c in node["children"] if isinstance(c, int) and not isinstance(c, bool) and 0 <= c < n]
                if isinstance(node, dict) and isinstance(node.get("children"), list) else [] for node in nodes]
    has_parent = [False] * n
    for listed in children:
        for c in listed:
            has_parent[c] = True
    level = [0] * n  # 0: not reached yet
    stack = [(r, 1) for r in reversed(range(n)) if not has_parent[r]]
    while stack:
        i, depth = stack.pop()
        if level[i]:
            continue  # listed by two parents: walked once
        level[i] = depth
        if depth > MAX_DEPTH:
            return f"nodes[{i}]", f"is {depth} levels deep in the node hierarchy; at most {MAX_DEPTH} are read"
        stack.extend((c, depth + 1) for c in reversed(children[i]) if not level[c])
    return None


def check_structure(f: GltfFile) -> None:
    """The file-level limits of :func:`structure_problems`, the first one crossed refused, before anything is
    read."""
    for where, problem in structure_problems(f.doc):
        f.fail(where, problem)


def declared_count(f: GltfFile, accessor: Any) -> int:
    """The ``count`` accessor ``accessor`` declares (0 when it is malformed: the reader refuses it by name when it
    decodes it)."""
    accessors = f.doc.get("accessors")
    if not (isinstance(accessor, int) and isinstance(accessors, list) and 0 <= accessor < len(accessors)):
        return 0
    a = accessors[accessor]
    count = a.get("count") if isinstance(a, dict) else None
    return count if isinstance(count, int) and not isinstance(count, bool) and count > 0 else 0


class SceneSize:
    """What the default scene stores, summed as the reader plans it and checked against the limits as it grows.

    The reader adds each mesh instance, each group of primitives sharing their vertices (stored once per
    instance) and each primitive's triangles before it decodes any accessor.
    """

    def __init__(self, f: GltfFile) -> None:
        self.f = f
        self.primitives = self.vertices = self.repeated = self.triangles = self.morph_values = 0

    def add_instance(self, node: int, mesh: int, n_primitives: int) -> None:
        """Mesh ``mesh`` instanced at node ``node`` (the instances themselves were counted with the file's
        nodes, :func:`structure_problems`): its primitives stored once more."""
        self.primitives += n_primitives
        if self.primitives > MAX_PRIMITIVES:
            self.f.fail(f"nodes[{node}].mesh", f"mesh {mesh}'s {n_primitives} primitives bring the scene's to "
                                               f"{self.primitives}; at most {MAX_PRIMITIVES} are stored (each "
                                               "instance counts)")

    def add_repeat(self, node: int, mesh: int, n_vertices: int) -> None:
        """Mesh ``mesh``, already stored, instanced again at node ``node``: its ``n_vertices`` stored again."""
        self.repeated += n_vertices
        if self.repeated > MAX_REPEATED_VERTICES:
            self.f.fail(f"nodes[{node}].mesh", f"another instance of mesh {mesh} ({n_vertices} vertices) brings the "
                                               f"vertices stored again for repeated instances to {self.repeated}; at "
                                               f"most {MAX_REPEATED_VERTICES}")

    def add_vertices(self, where: str, attributes: dict, n_targets: int) -> int:
        """A group of primitives sharing ``attributes`` (``where``: the first of them) stored once more; its
        declared vertex count. The scene's vertices are refused past the limit when more than this group
        makes them: a group alone is bounded by its POSITION accessor's own checks against its buffer view
        (a declared count the file cannot back is refused there, by the accessor's path). Its morph values
        (vertices × targets) are bounded in every case, since a target accessor without a buffer view costs
        the file nothing."""
        n = declared_count(self.f, attributes.get("POSITION"))
        self.vertices += n
        self.morph_values += n * n_targets
        if self.vertices > MAX_VERTICES and self.vertices > n:  # one group alone: its accessor's bounds judge it
            self.f.fail(f"{where}.attributes.POSITION", f"{n} vertices bring the scene's stored vertices to "
                                                        f"{self.vertices}; at most {MAX_VERTICES} (each instance "
                                                        "counts)")
        if self.morph_values > MAX_MORPH_VALUES:
            self.f.fail(f"{where}.targets", f"{n_targets} morph targets of {n} vertices bring the scene's morph "
                                            f"values to {self.morph_values}; at most {MAX_MORPH_VALUES} (each "
                                            "instance counts)")
        return n

    def add_triangles(self, where: str, primitive: dict, n_vertices: int) -> None:
        """Primitive ``primitive`` (at ``where``) over a group of ``n_vertices`` stored once more."""
        n = declared_count(self.f, primitive.get("indices")) if "indices" in primitive else n_vertices
        self.triangles += n // 3
        if self.triangles > MAX_TRIANGLES and self.triangles > n // 3:  # one primitive alone: as the vertices
            self.f.fail(where, f"{n // 3} triangles bring the scene's stored triangles to {self.triangles}; at "
                               f"most {MAX_TRIANGLES} (each instance counts)")


def check_kept_json(f: GltfFile, value: Any, where: str, depth: int = 1) -> None:
    """JSON the character keeps as it came (``value``, found at ``where`` at nesting level ``depth``): no deeper
    than :data:`MAX_KEPT_JSON_DEPTH`, every number finite. Walked without recursion."""
    stack = [(value, where, depth)]
    while stack:
        v, w, d = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            f.fail(w, f"{v!r}: a number the character keeps must be finite")
        if isinstance(v, (dict, list)):
            if d > MAX_KEPT_JSON_DEPTH:
                f.fail(w, f"nests {d} levels deep; the character keeps JSON at most {MAX_KEPT_JSON_DEPTH} levels "
                          "deep")
            items = v.items() if isinstance(v, dict) else enumerate(v)
            stack.extend((x, f"{w}.{k}" if isinstance(v, dict) else f"{w}[{k}]", d + 1)
                         for k, x in reversed(list(items)))
