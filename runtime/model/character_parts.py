"""The optional parts of a character that a glTF / VRM avatar brings: skeleton, look, expressions, layout.

A character imported from OBJ has none of them (every field ``None`` on
:class:`~facepuppet.runtime.model.character.Character`) and is drawn as before. A
character imported from glTF 2.0 / GLB / VRM has some or all:

* :class:`Skeleton`: the node hierarchy in its rest pose and, per vertex, up
  to four (node, weight) pairs. **Vertices, morph deltas and normals are stored
  in the rest pose, in world space** (the importer applies node transforms and
  the skins' inverse bind matrices once). So at rest every node's skinning
  matrix is the identity, and posing node ``j`` moves its vertices by
  ``D_j = G_j(posed) · G_j(rest)⁻¹`` (:meth:`Skeleton.pose_matrices`). Linear
  blend skinning of the stored vertices with these ``D_j`` is the glTF
  skinning of the file exactly when the file's bind pose is its node rest
  pose (the common case); the rest pose is what the file shows unanimated.
  A mesh without a skin on a node is stored as skinned to that node with
  weight 1, so a hat on the head bone turns with the head.
* :class:`Look`: texture coordinates, textures (RGBA pixels as in the image:
  sRGB-encoded) and the glTF/VRM material parameters per material.
* :class:`Expressions`: VRM expressions (0.x blendShapeGroups, 1.0
  expressions): each drives several shapes (morph targets) at bind weights
  0..1, with ``isBinary`` and the VRM 1.0 overrides.
* :class:`Layout`: which vertices and triangles came from which primitive of
  which mesh, so that ``export-character`` writes the meshes back as they were.
* ``normals`` (one section, ``vertex_normals``): the file's own rest normals,
  world space, unit length. Low-poly and toon avatars author hard edges and
  custom normals that area-weighted normals from the triangles lose (Godette's
  differ by 16° at the median); without them the renderer computes normals.

Frames: every character is stored +Y up, facing +Z (the ICT convention); a
VRM 0.x avatar (which faces −Z) is turned 180° about +Y on import and turned
back on export (``metadata["source"]["turned_y180"]``). glTF units are metres.

The tables sections of these parts are optional sections of kind
``character`` (schema version 2); a part is all of its sections or none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.files.tables import Section, TablesError
from facepuppet.runtime.model.geometry import quat_to_matrix
from facepuppet.runtime.model.material_model import SECTIONS as MATERIAL_MODEL_SECTIONS

# -- codes ----------------------------------------------------------------
ALPHA_MODES = {"OPAQUE": 0, "MASK": 1, "BLEND": 2}
SHADING = {"lit": 0, "unlit": 1, "toon": 2}
OVERRIDES = {"none": 0, "block": 1, "blend": 2}
# glTF sampler codes (the spec's GL enums); 0 = not given (the renderer's default: linear, repeat).
NEAREST, LINEAR = 9728, 9729
REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT = 10497, 33071, 33648

# Column meaning of the float tables (documented here once; the importer, renderer and exporter use them).
#: ``material_shading`` columns
SHADING_COLUMNS = ("shading", "double_sided", "shade_r", "shade_g", "shade_b", "shading_shift",
                   "shading_toony", "unused")
#: ``material_uv_transform`` columns (KHR_texture_transform): offset u, offset v, rotation (radians), scale u, v
UV_TRANSFORM_COLUMNS = ("offset_u", "offset_v", "rotation", "scale_u", "scale_v")
IDENTITY_UV_TRANSFORM = (0.0, 0.0, 0.0, 1.0, 1.0)
#: ``texture_info`` columns: first texel, width, height, mag filter, min filter, wrap s, wrap t
TEXTURE_INFO_COLUMNS = ("first_texel", "width", "height", "mag_filter", "min_filter", "wrap_s", "wrap_t")
#: ``expression_flags`` columns: is_binary (0/1), override blink, look at, mouth (:data:`OVERRIDES` codes)
EXPRESSION_FLAG_COLUMNS = ("is_binary", "override_blink", "override_look_at", "override_mouth")
#: ``primitives`` columns
PRIMITIVE_COLUMNS = ("first_vertex", "n_vertices", "first_triangle", "n_triangles", "mesh", "material")

#: The optional sections, by part (all of a part's sections or none).
PART_SECTIONS: dict[str, dict[str, Section]] = {
    "skeleton": {
        "node_parent": Section("int32", ("n_nodes",), "parent node index, -1 for a root; parents come first",
                               optional=True),
        "node_rest": Section("float32", ("n_nodes", 4, 4), "local rest transform, row-major, column vectors",
                             optional=True),
        "vertex_nodes": Section("uint16", ("n_vertices", 4), "the nodes each vertex follows", optional=True),
        "vertex_weights": Section("float32", ("n_vertices", 4), "their weights, each row sums to 1",
                                  optional=True),
    },
    "look": {
        "uv": Section("float32", ("n_vertices", 2), "TEXCOORD_0 (glTF: origin top-left)", optional=True),
        "material_base_color": Section("float32", ("n_materials", 4), "baseColorFactor, linear RGBA",
                                       optional=True),
        "material_emissive": Section("float32", ("n_materials", 3), "emissiveFactor, linear RGB", optional=True),
        "material_alpha": Section("float32", ("n_materials", 2), "alpha mode code, alpha cutoff", optional=True),
        "material_shading": Section("float32", ("n_materials", 8), "see SHADING_COLUMNS", optional=True),
        "material_texture": Section("int32", ("n_materials",), "base colour texture index, -1 none",
                                    optional=True),
        "material_uv_transform": Section("float32", ("n_materials", 5), "see UV_TRANSFORM_COLUMNS",
                                         optional=True),
        "texture_info": Section("int32", ("n_textures", 7), "see TEXTURE_INFO_COLUMNS", optional=True),
        "texture_pixels": Section("uint8", ("n_texels", 4), "RGBA as in the image (sRGB), rows top first",
                                  optional=True),
    },
    "expressions": {
        "expression_offsets": Section("int64", ("n_expressions+1",), "CSR row starts per expression",
                                      optional=True),
        "expression_bind_shape": Section("uint32", ("n_binds",), "shape each bind drives", optional=True),
        "expression_bind_weight": Section("float32", ("n_binds",), "its weight 0..1 at expression weight 1",
                                          optional=True),
        "expression_flags": Section("int32", ("n_expressions", 4), "see EXPRESSION_FLAG_COLUMNS",
                                    optional=True),
    },
    "layout": {
        "primitives": Section("int64", ("n_primitives", 6), "see PRIMITIVE_COLUMNS", optional=True),
    },
    "normals": {
        "vertex_normals": Section("float32", ("n_vertices", 3), "rest normals from the file, unit length",
                                  optional=True),
    },
    # MToon outline / rim / UV animation, metallic-roughness and the material binds (runtime.material_model)
    "material_model": MATERIAL_MODEL_SECTIONS,
}
#: Channel groups of the parts: group -> (part, named dimension its length must equal, or None); the
#: ``normals`` and ``material_model`` parts have none.
PART_CHANNELS = {"nodes": ("skeleton", "n_nodes"), "textures": ("look", "n_textures"),
                 "expressions": ("expressions", "n_expressions"), "meshes": ("layout", None)}


def _fail(field_name: str, problem: str):
    raise TablesError(None, field_name, problem)


def _readonly(*arrays: np.ndarray) -> None:
    for a in arrays:
        a.setflags(write=False)


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Nodes in their rest pose and the nodes each vertex follows (see the module doc).

    Attributes
    ----------
    names : tuple of n_nodes str, distinct
    parent : ndarray of shape (n_nodes,), int32, -1 for a root, else a smaller index
    rest_local : ndarray of shape (n_nodes, 4, 4), float32, local rest transform of each node
    vertex_nodes : ndarray of shape (n_vertices, 4), uint16, node indices
    vertex_weights : ndarray of shape (n_vertices, 4), float32, >= 0, rows summing to 1
    bones : dict str -> int, VRM humanoid bone name (``head``, ``neck``, ``hips``, …) -> node index
    """

    names: tuple[str, ...]
    parent: np.ndarray
    rest_local: np.ndarray
    vertex_nodes: np.ndarray
    vertex_weights: np.ndarray
    bones: dict

    def check(self, n_vertices: int) -> None:
        n = len(self.names)
        if self.parent.shape != (n,) or self.rest_local.shape != (n, 4, 4):
            _fail("node_parent", f"{n} node names but parent {self.parent.shape}, rest {self.rest_local.shape}")
        if n and np.any((self.parent >= np.arange(n)) | (self.parent < -1)):
            _fail("node_parent", "each parent must be -1 or an earlier node (parents first)")
        if self.vertex_nodes.shape != (n_vertices, 4) or self.vertex_weights.shape != (n_vertices, 4):
            _fail("vertex_nodes", f"expected ({n_vertices}, 4) nodes and weights per vertex")
        if n_vertices and int(self.vertex_nodes.max()) >= n:
            _fail("vertex_nodes", f"node index {int(self.vertex_nodes.max())} out of range for {n} nodes")
        w = self.vertex_weights
        if np.any(w < 0) or np.any(np.abs(w.sum(axis=1) - 1.0) > 1e-3):
            _fail("vertex_weights", "weights must be >= 0 and sum to 1 per vertex")
        for bone, node in self.bones.items():
            if not (isinstance(node, int) and 0 <= node < n):
                _fail(f"humanoid.{bone}", f"node {node!r} out of range for {n} nodes")
        _readonly(self.parent, self.rest_local, self.vertex_nodes, self.vertex_weights)

    @property
    def n_nodes(self) -> int:
        return len(self.names)

    def global_transforms(self, local: np.ndarray | None = None) -> np.ndarray:
        """World transforms (n_nodes, 4, 4) float64 of ``local`` (default: the rest pose), parents first."""
        local = self.rest_local if local is None else local
        out = np.empty((self.n_nodes, 4, 4))
        for j in range(self.n_nodes):
            p = int(self.parent[j])
            out[j] = local[j] if p < 0 else out[p] @ local[j]
        return out

    def descendants(self, node: int) -> np.ndarray:
        """Boolean mask (n_nodes,) of ``node`` and every node below it."""
        mask = np.zeros(self.n_nodes, dtype=bool)
        mask[node] = True
        for j in range(node + 1, self.n_nodes):  # parents come first
            if self.parent[j] >= 0 and mask[self.parent[j]]:
                mask[j] = True
        return mask

    def pose_matrices(self, rotations: dict[int, np.ndarray] | None = None) -> np.ndarray:
        """Skinning matrices ``D_j`` (n_nodes, 4, 4) float32 for world-frame rotations of some nodes.

        ``rotations`` maps a node index to a quaternion (x, y, z, w) turning that
        node and everything below it about the node's rest position, in the
        world frame; nested rotations compose from the root down (a neck turn
        carries the head, whose own turn is then about its carried position).
        None or {} gives identities.
        """
        d = np.tile(np.eye(4), (self.n_nodes, 1, 1))
        if rotations:
            rest = self.global_transforms()
            for node in sorted(rotations):  # parents first: a parent's turn carries its children
                r = np.eye(4)
                r[:3, :3] = quat_to_matrix(rotations[node])
                pivot = d[node] @ rest[node][:, 3]
                t = np.eye(4)
                t[:3, 3] = pivot[:3]
                turn = t @ r @ np.linalg.inv(t)
                mask = self.descendants(node)
                d[mask] = turn @ d[mask]
        return d.astype(np.float32)


@dataclass(frozen=True, eq=False)
class Look:
    """Texture coordinates, textures and glTF material parameters (columns: see the module constants).

    Attributes
    ----------
    uv : ndarray (n_vertices, 2) float32
    base_color : ndarray (n_materials, 4) float32, linear RGBA
    emissive : ndarray (n_materials, 3) float32
    alpha : ndarray (n_materials, 2) float32: :data:`ALPHA_MODES` code, cutoff
    shading : ndarray (n_materials, 8) float32: :data:`SHADING_COLUMNS`
    texture : ndarray (n_materials,) int32, index into textures or -1
    uv_transform : ndarray (n_materials, 5) float32: :data:`UV_TRANSFORM_COLUMNS`
    texture_names : tuple of n_textures str
    texture_info : ndarray (n_textures, 7) int32: :data:`TEXTURE_INFO_COLUMNS`
    texture_pixels : ndarray (n_texels, 4) uint8, all textures' RGBA rows, top row first
    """

    uv: np.ndarray
    base_color: np.ndarray
    emissive: np.ndarray
    alpha: np.ndarray
    shading: np.ndarray
    texture: np.ndarray
    uv_transform: np.ndarray
    texture_names: tuple[str, ...]
    texture_info: np.ndarray
    texture_pixels: np.ndarray

    def check(self, n_vertices: int, n_materials: int) -> None:
        for name, arr, shape in (("uv", self.uv, (n_vertices, 2)), ("material_base_color", self.base_color,
                                 (n_materials, 4)), ("material_emissive", self.emissive, (n_materials, 3)),
                                 ("material_alpha", self.alpha, (n_materials, 2)),
                                 ("material_shading", self.shading, (n_materials, 8)),
                                 ("material_texture", self.texture, (n_materials,)),
                                 ("material_uv_transform", self.uv_transform, (n_materials, 5)),
                                 ("texture_info", self.texture_info, (len(self.texture_names), 7))):
            if arr.shape != shape:
                _fail(name, f"expected shape {shape}, found {arr.shape}")
        n_tex = len(self.texture_names)
        if n_materials and (int(self.texture.max(initial=-1)) >= n_tex or int(self.texture.min(initial=0)) < -1):
            _fail("material_texture", f"texture index out of range for {n_tex} textures")
        if not set(np.unique(self.alpha[:, 0]).tolist()) <= set(ALPHA_MODES.values()):
            _fail("material_alpha", "alpha mode codes must be 0 (OPAQUE), 1 (MASK) or 2 (BLEND)")
        for t in range(n_tex):
            first, w, h = (int(x) for x in self.texture_info[t, :3])
            if w <= 0 or h <= 0 or first < 0 or first + w * h > len(self.texture_pixels):
                _fail("texture_info", f"texture {t} ({self.texture_names[t]!r}): {w}x{h} at texel {first} "
                                      f"does not fit in {len(self.texture_pixels)} texels")
        _readonly(self.uv, self.base_color, self.emissive, self.alpha, self.shading, self.texture,
                  self.uv_transform, self.texture_info, self.texture_pixels)

    def image(self, t: int) -> np.ndarray:
        """Texture ``t`` as ndarray (height, width, 4) uint8, top row first (a view)."""
        first, w, h = (int(x) for x in self.texture_info[t, :3])
        return self.texture_pixels[first:first + w * h].reshape(h, w, 4)


@dataclass(frozen=True, eq=False)
class Expressions:
    """VRM expressions: each a weighted set of shapes (CSR over binds).

    Attributes
    ----------
    names : tuple of n_expressions str, the channel names (a preset's VRM 0.x spelling from
        :data:`~facepuppet.runtime.mapping.vrm_names.VRM0_PRESETS`, e.g. ``Blink_L``; a custom one's own name)
    presets : tuple of n_expressions str, the VRM 0.x preset spelling, "" for a custom expression
    offsets : ndarray (n_expressions + 1,) int64
    bind_shape : ndarray (n_binds,) uint32, character shape index
    bind_weight : ndarray (n_binds,) float32, 0..1 (VRM 0.x's 0..100 divided by 100)
    flags : ndarray (n_expressions, 4) int32: :data:`EXPRESSION_FLAG_COLUMNS`
    """

    names: tuple[str, ...]
    presets: tuple[str, ...]
    offsets: np.ndarray
    bind_shape: np.ndarray
    bind_weight: np.ndarray
    flags: np.ndarray

    def check(self, n_shapes: int) -> None:
        n = len(self.names)
        if len(self.presets) != n or self.flags.shape != (n, 4):
            _fail("expression_flags", f"{n} expressions need {n} presets and ({n}, 4) flags")
        o = self.offsets
        if len(o) != n + 1 or o[0] != 0 or np.any(np.diff(o) < 0) or o[-1] != len(self.bind_shape):
            _fail("expression_offsets", "must start at 0, never decrease, have n + 1 entries, end at n_binds")
        if len(self.bind_weight) != len(self.bind_shape):
            _fail("expression_bind_weight", "one weight per bind")
        if len(self.bind_shape) and int(self.bind_shape.max()) >= n_shapes:
            _fail("expression_bind_shape", f"shape index out of range for {n_shapes} shapes")
        _readonly(self.offsets, self.bind_shape, self.bind_weight, self.flags)

    @property
    def n_expressions(self) -> int:
        return len(self.names)

    def binds(self, e: int) -> tuple[np.ndarray, np.ndarray]:
        """(shape indices, weights) of expression ``e``."""
        sl = slice(int(self.offsets[e]), int(self.offsets[e + 1]))
        return self.bind_shape[sl], self.bind_weight[sl]

    def dense(self, n_shapes: int) -> np.ndarray:
        """The binds as a matrix (n_expressions, n_shapes) float32: shape weights = its transpose @ weights."""
        m = np.zeros((self.n_expressions, n_shapes), dtype=np.float32)
        for e in range(self.n_expressions):
            s, w = self.binds(e)
            np.add.at(m[e], s.astype(np.int64), w)
        return m


@dataclass(frozen=True, eq=False)
class Layout:
    """Where each glTF primitive's vertices and triangles sit in the character (for export).

    Attributes
    ----------
    mesh_names : tuple of n_meshes str (one per mesh instance on a node)
    primitives : ndarray (n_primitives, 6) int64: :data:`PRIMITIVE_COLUMNS`
    """

    mesh_names: tuple[str, ...]
    primitives: np.ndarray

    def check(self, n_vertices: int, n_triangles: int, n_materials: int) -> None:
        p = self.primitives
        if p.ndim != 2 or p.shape[1] != 6:
            _fail("primitives", f"expected shape (n_primitives, 6), found {p.shape}")
        if len(p) and (np.any(p < 0) or np.any(p[:, 0] + p[:, 1] > n_vertices)
                       or np.any(p[:, 2] + p[:, 3] > n_triangles) or int(p[:, 4].max()) >= len(self.mesh_names)
                       or int(p[:, 5].max()) >= max(n_materials, 1)):
            _fail("primitives", "a primitive's vertex or triangle range, mesh or material is out of range")
        _readonly(self.primitives)


def check_normals(normals: np.ndarray, n_vertices: int) -> None:
    """Refuse rest normals that are not (n_vertices, 3) unit vectors (TablesError naming ``vertex_normals``)."""
    if normals.shape != (n_vertices, 3):
        _fail("vertex_normals", f"expected shape ({n_vertices}, 3), found {normals.shape}")
    if n_vertices and np.any(np.abs(np.linalg.norm(normals, axis=1) - 1.0) > 1e-3):
        _fail("vertex_normals", "must be unit length")
    _readonly(normals)


def identity_look(n_vertices: int, n_materials: int) -> dict[str, np.ndarray]:
    """Arrays of a :class:`Look` that changes nothing (white factor, opaque, lit, no texture), for tests and tools."""
    return {
        "uv": np.zeros((n_vertices, 2), np.float32),
        "base_color": np.ones((n_materials, 4), np.float32),
        "emissive": np.zeros((n_materials, 3), np.float32),
        "alpha": np.tile(np.array([ALPHA_MODES["OPAQUE"], 0.5], np.float32), (n_materials, 1)),
        "shading": np.zeros((n_materials, 8), np.float32),
        "texture": np.full(n_materials, -1, np.int32),
        "uv_transform": np.tile(np.array(IDENTITY_UV_TRANSFORM, np.float32), (n_materials, 1)),
    }
