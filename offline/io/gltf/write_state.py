"""What one export has written so far: the core writer fills it, the extension writers read it.

The core steps (:mod:`.write_skeleton`, :mod:`.write_meshes`,
:mod:`.write_materials`) write the glTF 2.0 document; the extension writers
(the ordered lists in :mod:`.write`) then need to know where things went:
which node holds each mesh (a VRM 1.0 bind names a node), the target index of
each shape on each mesh (a bind names a target), the written materials, and
how the file's nodes were renumbered (for the VRM parts kept from the file).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.io.gltf.write_buffer import Buffer

Progress = Callable[[int, int, str], None]
GENERATOR = "facepuppet export-character"


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
    n_springs: int = 0
    added_expressions: list[str] = field(default_factory=list)
    turned_y180: bool = False
    bytes: int = 0
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)


@dataclass(eq=False)
class WriteState:
    """One export of character ``c`` as ``fmt`` ("glb", "gltf", "vrm0", "vrm1").

    ``turn``: everything is turned 180° about +Y (a VRM 0.x faces −Z). The other fields are filled by the
    steps named beside them.
    """

    c: Character
    fmt: str
    progress: Progress | None
    buf: Buffer = field(default_factory=Buffer)
    turn: bool = False
    summary: ExportSummary = field(default_factory=lambda: ExportSummary(Path(), ""))
    ext_used: set[str] = field(default_factory=set)
    # write.py: the vertex data in the file's frame and units
    scale: float = 1.0
    vertices: np.ndarray | None = None  # (n_vertices, 3) float32
    normals: np.ndarray | None = None  # (n_vertices, 3) float32
    opacity: np.ndarray | None = None  # (n_vertices,) float32, an OBJ rig's thin layers' fade, or None
    delta_pos: np.ndarray | None = None
    delta_nrm: np.ndarray | None = None
    # write_skeleton
    n_skeleton_nodes: int = 0
    joints: np.ndarray | None = None  # skeleton nodes the skinned meshes' vertices follow (the skin's joints)
    rigid: list[bool] = field(default_factory=list)  # per mesh: follows only its own node, written unskinned
    # write_meshes
    primitives: list = field(default_factory=list)  # (first vertex, n vertices, triangles, mesh, material)
    mesh_names: list[str] = field(default_factory=list)
    host_names: list[str] = field(default_factory=list)  # names of the new nodes that would hold the meshes
    targets: list[list[int]] = field(default_factory=list)  # shapes of each mesh, in target order
    target_index: list[dict[int, int]] = field(default_factory=list)  # per mesh: shape -> target index
    host: list[int] = field(default_factory=list)  # the node holding each mesh (-1 until placed: a new node)
    # write_materials
    materials: list[dict] = field(default_factory=list)
    file_texture: dict[int, int] = field(default_factory=dict)  # file texture -> written texture (kept_parts)
    file_image: dict[int, int] = field(default_factory=dict)  # file image -> written image (kept_parts)
    textures: list[dict] = field(default_factory=list)  # the written textures (a later part may add one)

    def warn(self, text: str) -> None:
        self.summary.warnings.append(text)

    def points(self, v: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """Points or vectors ``v`` (n, 3) in the file's frame: scaled, turned for a VRM 0.x; float32."""
        out = np.asarray(v, dtype=np.float64) * scale
        if self.turn:
            out = out * (-1.0, 1.0, -1.0)
        return out.astype(np.float32)

    def kept_vrm(self) -> dict:
        """A copy of the VRM extension kept on import (``settings.source.vrm_extension``) when the character
        came from the VRM version being written, else {}: the parts of it no reader turned into the character's
        own (first person, look-at, spring bones) go back from it."""
        raw = self.c.source.get("vrm_extension")
        if self.c.source.get("format") != self.fmt or not isinstance(raw, dict):
            return {}
        return copy.deepcopy(raw)

    def node_map(self) -> Callable[[Any], int | None]:
        """file node index -> written node index (``settings.source.node_from_file``), or None when the node
        is not in the character."""
        src = self.c.source.get("node_from_file")
        n = self.n_skeleton_nodes
        inverse = {int(o): s for s, o in enumerate(src)} if isinstance(src, list) else {i: i for i in range(n)}

        def remap(node: Any) -> int | None:
            if isinstance(node, bool) or not isinstance(node, int):
                return None
            s = inverse.get(node)
            return s if s is not None and s < n else None
        return remap
