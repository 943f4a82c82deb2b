"""What one glTF read has found so far: the core reader fills it, the extension readers complete it.

The core steps (:mod:`.read_nodes`, :mod:`.read_meshes`, :mod:`.read_materials`)
read what every glTF 2.0 file has; each extension reader (the ordered list in
:mod:`.read`) then adds what its extension or VRM concept says: the material
rows it changes, the humanoid bones, the expressions, the meta. Keeping this
state in one record lets a reader of one extension see what the core found
without knowing about the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from facepuppet.runtime.model.character_parts import Expressions

from facepuppet.offline.io.gltf_container import GltfFile


@dataclass(eq=False)
class LookRows:
    """The per-material look being read, float64 until the character is built (one row per stored material).

    Attributes
    ----------
    base : ndarray (n_materials, 4), linear RGBA base colour factor
    emissive : ndarray (n_materials, 3)
    alpha : ndarray (n_materials, 2), (ALPHA_MODES code, cutoff)
    shading : ndarray (n_materials, 8), the ``SHADING_COLUMNS`` of :mod:`facepuppet.runtime.model.character_parts`
    texture : ndarray (n_materials,), int64, stored texture index or -1
    uv_transform : ndarray (n_materials, 5), KHR_texture_transform offset u, v, rotation, scale u, v
    """

    base: np.ndarray
    emissive: np.ndarray
    alpha: np.ndarray
    shading: np.ndarray
    texture: np.ndarray
    uv_transform: np.ndarray


@dataclass(eq=False)
class ReadState:
    """One read of a glTF / VRM file.

    ``format`` is "gltf", "glb", "vrm0" or "vrm1"; ``vrm0`` / ``vrm1`` the file's ``VRM`` / ``VRMC_vrm``
    extension object (or None); ``turn``: the stored frame is the file's turned 180° about +Y (VRM 0.x
    faces −Z). The other fields are filled by the steps named beside them.
    """

    f: GltfFile
    format: str
    vrm0: dict | None
    vrm1: dict | None
    turn: bool
    warnings: list[str] = field(default_factory=list)
    # read_nodes: the hierarchy renumbered parents first ("stored" order)
    node_from_file: np.ndarray | None = None  # (n_nodes,) int64, file node of each stored node
    stored_of: dict[int, int] = field(default_factory=dict)  # file node -> stored node
    parent: np.ndarray | None = None  # (n_nodes,) int64, stored parent or -1
    rest_local: np.ndarray | None = None  # (n_nodes, 4, 4) float64, stored frame
    world: np.ndarray | None = None  # (n_nodes, 4, 4) float64, stored frame
    node_names: list[str] = field(default_factory=list)
    # read_meshes
    geo: dict[str, Any] = field(default_factory=dict)
    shape_names: tuple[str, ...] = ()
    deltas: dict[str, np.ndarray] = field(default_factory=dict)
    # read_materials
    material_names: tuple[str, ...] = ()
    material_params: np.ndarray | None = None
    look: LookRows | None = None
    texture_names: tuple[str, ...] = ()
    texture_info: np.ndarray | None = None
    texture_pixels: np.ndarray | None = None
    # extension readers
    bones: dict[str, int] = field(default_factory=dict)
    expressions: Expressions | None = None
    meta: dict = field(default_factory=dict)
    credits: str = ""
    kept: dict[str, Any] = field(default_factory=dict)  # kept_parts: raw JSON and textures for export
    springs: dict = field(default_factory=dict)  # read_springs: chains and colliders
    look_at: dict = field(default_factory=dict)  # read_look_at: type, range maps, eye nodes

    @property
    def doc(self) -> dict:
        return self.f.doc

    def warn(self, text: str) -> None:
        self.warnings.append(text)


def extensions_of(o: Any) -> dict:
    """The ``extensions`` object of a glTF object (empty when it has none or it is malformed)."""
    e = o.get("extensions", {}) if isinstance(o, dict) else {}
    return e if isinstance(e, dict) else {}


def target_names(extras: Any) -> list:
    """``extras.targetNames``: the morph target names Blender and UniVRM write on a mesh or primitive."""
    names = extras.get("targetNames") if isinstance(extras, dict) else None
    return names if isinstance(names, list) else []
