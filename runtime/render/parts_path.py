"""Drawing a character that carries glTF / VRM parts (skeleton, look): the renderer's pieces for it.

:class:`~facepuppet.runtime.render.renderer.FaceRenderer` draws a character
with a :class:`~facepuppet.runtime.model.character_parts.Look` or a
:class:`~facepuppet.runtime.model.character_parts.Skeleton` through ``character.glsl``
with what this module prepares; a character without parts is drawn through
``face.glsl`` exactly as before.

* Draw groups: the triangles of one material (a blended material split further
  per glTF primitive), OPAQUE and MASK first (single-sided ones back-face
  culled, double-sided ones not; their triangles in compact patches,
  :mod:`~facepuppet.runtime.render.triangle_order`), then BLEND groups back to front by the view
  depth of their centre, sorted every frame (a handful of groups); inside a
  blended group the triangles are sorted back to front once, for the framed
  camera (the camera does not move; a head turn changes the order little).
* Materials: one std140 uniform buffer per material (``Material`` in
  ``character.glsl``), so a draw call binds one buffer and one texture.
* Textures: ``SRGB8_ALPHA8`` (the sampler decodes sRGB to linear), the glTF
  sampler's filters (mipmaps for a mipmapping minifying filter; default
  trilinear, as glTF viewers do) and wraps (mirrored repeat folded in the shader).
* Head pose: :class:`HeadPose` turns the humanoid ``head`` bone and, by
  :data:`NECK_SHARE`, the ``neck`` (the body stays); without a head bone the
  renderer turns the whole character about its pivot, as before.
* CPU skinning: :class:`CpuSkinner`, linear blend skinning in NumPy of the
  vertices a head pose can move.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.model.character_parts import (
    ALPHA_MODES,
    CLAMP_TO_EDGE,
    MIRRORED_REPEAT,
    NEAREST,
    Look,
    identity_look,
)
from facepuppet.runtime.model.geometry import quat_to_matrix
from facepuppet.runtime.model.material_model import MaterialModel, default_material_model
from facepuppet.runtime.render.material_binds import MaterialRows
from facepuppet.runtime.render.triangle_order import cache_order

#: Share of a head turn given to the neck bone (the head bone takes the rest); 0.3, as avatar apps do.
NECK_SHARE = 0.3
_SRGB8_ALPHA8 = 0x8C43
_MIPMAP_MIN = {9984: moderngl.NEAREST_MIPMAP_NEAREST, 9985: moderngl.LINEAR_MIPMAP_NEAREST,
               9986: moderngl.NEAREST_MIPMAP_LINEAR, 9987: moderngl.LINEAR_MIPMAP_LINEAR}
_BLEND = ALPHA_MODES["BLEND"]


def has_parts(character: Character) -> bool:
    """True when the character is drawn through ``character.glsl`` (it has a look or a skeleton)."""
    return character.look is not None or character.skeleton is not None


def look_of(character: Character) -> Look:
    """The character's look, or one that draws its vertex colours lit and opaque (a skeleton without a look)."""
    if character.look is not None:
        return character.look
    n_m = len(character.material_names)
    return Look(texture_names=(), texture_info=np.zeros((0, 7), np.int32),
                texture_pixels=np.zeros((0, 4), np.uint8), **identity_look(character.n_vertices, n_m))


def vertex_attributes(character: Character, opacity: np.ndarray | None = None) -> np.ndarray:
    """Per-vertex [colour 3, uv 2, joints 4, weights 4, opacity 1] float32 (joints exact as floats), (n, 14).

    ``opacity`` (n,), default 1: multiplies the material's alpha (the renderer gives the thin layers of an
    OBJ rig's kinds, eye occlusion, films, lashes, their fade: ``layers.vertex_opacity``).
    """
    c = character
    out = np.zeros((c.n_vertices, 14), np.float32)
    out[:, :3] = c.vertex_color
    out[:, 3:5] = look_of(c).uv
    if c.skeleton is not None:
        out[:, 5:9] = c.skeleton.vertex_nodes
        out[:, 9:13] = c.skeleton.vertex_weights
    else:
        out[:, 9] = 1.0
    out[:, 13] = 1.0 if opacity is None else opacity
    return out


def uv_matrix(offset_u: float, offset_v: float, rotation: float, scale_u: float,
              scale_v: float) -> np.ndarray:
    """KHR_texture_transform ``T · R · S`` as its two rows acting on (u, v, 1), (2, 3) float64."""
    c, s = np.cos(rotation), np.sin(rotation)
    t = np.array([[1, 0, offset_u], [0, 1, offset_v], [0, 0, 1]], float)
    r = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]], float)
    return (t @ r @ np.diag([scale_u, scale_v, 1.0]))[:2]


def material_model_of(character: Character) -> MaterialModel:
    """The character's material model, or one with no MToon extras, the studio lighting and no binds."""
    if character.material_model is not None:
        return character.material_model
    return default_material_model(len(character.material_names))


def material_block(character: Character, m: int, rows: MaterialRows | None = None) -> bytes:
    """The std140 ``Material`` block of material ``m`` (14 vec4, see character.glsl); ``rows``: the values
    that expressions' material binds change (default: the character's own)."""
    look = look_of(character)
    rows = rows if rows is not None else MaterialRows.of(character)
    params = character.material_params[m]
    mt = material_model_of(character).mtoon[m]
    pbr = material_model_of(character).pbr[m]
    t = int(look.texture[m])
    shading = look.shading[m]
    mirror = (0.0, 0.0)
    if t >= 0:
        wrap_s, wrap_t = (int(x) for x in look.texture_info[t, 5:7])
        mirror = (float(wrap_s == MIRRORED_REPEAT), float(wrap_t == MIRRORED_REPEAT))
    uv = uv_matrix(*(float(x) for x in rows.uv_transform[m]))
    block = np.zeros((14, 4), np.float32)
    block[0] = rows.base_color[m]
    block[1] = (*rows.emissive[m], look.alpha[m, 1])
    block[2] = (*rows.shade[m], shading[5])
    block[3] = (look.alpha[m, 0], shading[0], shading[6], float(t >= 0))
    block[4] = (*mirror, params[0], max(float(params[1]), 1.0))
    block[5, :3], block[6, :3] = uv[0], uv[1]
    block[7] = (*rows.outline[m], mt[5])
    block[8, 0] = mt[1]
    block[9] = (*rows.rim[m], mt[10])
    block[10, :2] = (mt[11], mt[12])
    block[11, :3] = mt[13:16]
    block[12, :2] = pbr[:2]
    block[13, :3] = mt[17:20]
    return block.tobytes()


#: The #defines that make one variant of ``character.glsl``, in the order of a variant key
VARIANT_DEFINES = ("ALPHA_MODE", "SHADING", "TEXTURED", "MIRROR", "KIND", "PBR", "RIM", "UV_ANIM", "MATCAP",
                   "RIM_TEX", "UV_MASK", "OUTLINE", "OUTLINE_TEX")
_SURFACE_DEFINES = len(VARIANT_DEFINES) - 2
_LIT, _TOON = 0, 2


def material_variant(character: Character, m: int) -> tuple[int, ...]:
    """The variant of material ``m``'s surface: (alpha mode, shading code, textured, mirrored wrap, lighting
    kind, metallic-roughness, rim, UV animation, matcap, rim texture, UV animation mask, 0, 0), each an int;
    the kind
    (:data:`~facepuppet.runtime.model.character.MATERIAL_KINDS`) only for lit materials of the studio
    lighting (eyes, teeth, lashes ... as ``face.glsl`` draws them), else 0; metallic-roughness 1 for a lit
    glTF material (2 with its texture); rim (parametric rim or matcap) and its textures and the UV animation
    and its mask for toon materials whose MToon has them.

    ``character.glsl`` is compiled once per distinct variant with these as #defines
    (:data:`VARIANT_DEFINES`): a variant has no branch, texture fetch or discard it does not use. Its
    outline pass is :func:`outline_variant`.
    """
    look = look_of(character)
    model = material_model_of(character)
    t = int(look.texture[m])
    mirrored = False
    if t >= 0:
        wrap_s, wrap_t = (int(x) for x in look.texture_info[t, 5:7])
        mirrored = MIRRORED_REPEAT in (wrap_s, wrap_t)
    shading = int(round(float(look.shading[m][0])))
    pbr = 0
    if shading == _LIT and model.pbr[m, 3] > 0.5:
        pbr = 2 if model.pbr[m, 2] >= 0 else 1
    kind = int(round(float(character.material_params[m, 2]))) if shading == _LIT and not pbr else 0
    mt = model.mtoon[m]
    matcap = int(shading == _TOON and mt[20] >= 0 and bool(np.any(mt[17:20] > 0)))
    rim = int(shading == _TOON and (bool(np.any(mt[7:10] > 0)) or bool(matcap)))
    uv_anim = int(bool(np.any(mt[13:16] != 0)))
    return (int(round(float(look.alpha[m, 0]))), shading, int(t >= 0), int(mirrored), kind, pbr, rim, uv_anim,
            matcap, int(rim and mt[16] >= 0), int(uv_anim and mt[21] >= 0), 0, 0)


def outline_variant(character: Character, m: int) -> tuple[int, ...] | None:
    """The variant of material ``m``'s outline pass (its surface variant with OUTLINE = the width mode and
    OUTLINE_TEX), or None when it draws none (mode none, width 0, or alpha BLEND)."""
    mt = material_model_of(character).mtoon[m]
    look = look_of(character)
    if int(mt[0]) == 0 or mt[1] <= 0 or int(round(float(look.alpha[m, 0]))) == _BLEND:
        return None
    return (*material_variant(character, m)[:_SURFACE_DEFINES], int(mt[0]), int(mt[6] >= 0))


def variant_defines(variant: tuple[int, ...]) -> dict[str, int]:
    """The #defines of a variant key from :func:`material_variant`."""
    return dict(zip(VARIANT_DEFINES, variant))


def make_textures(ctx: moderngl.Context, look: Look | MaterialModel, srgb: bool = True) -> list:
    """One moderngl texture per texture of a look (sRGB: colours) or of a material model (``srgb=False``:
    metallic-roughness, outline width, linear data), with its glTF sampler's filters and wraps."""
    out = []
    for t in range(len(look.texture_names)):
        image = np.ascontiguousarray(look.image(t))
        h, w = image.shape[:2]
        fmt = {"internal_format": _SRGB8_ALPHA8} if srgb else {}
        tex = ctx.texture((w, h), 4, image.tobytes(), **fmt)  # row 0 = v 0 (glTF)
        mag, minf, wrap_s, wrap_t = (int(x) for x in look.texture_info[t, 3:7])
        mag_gl = moderngl.NEAREST if mag == NEAREST else moderngl.LINEAR
        if minf in _MIPMAP_MIN or minf == 0:
            tex.build_mipmaps()
            min_gl = _MIPMAP_MIN.get(minf, moderngl.LINEAR_MIPMAP_LINEAR)
        else:
            min_gl = moderngl.NEAREST if minf == NEAREST else moderngl.LINEAR
        tex.filter = (min_gl, mag_gl)
        # REPEAT (and 0, the default) repeat in the sampler; CLAMP and MIRRORED clamp (the shader mirrors).
        tex.repeat_x = wrap_s not in (CLAMP_TO_EDGE, MIRRORED_REPEAT)
        tex.repeat_y = wrap_t not in (CLAMP_TO_EDGE, MIRRORED_REPEAT)
        out.append(tex)
    return out


@dataclass(frozen=True)
class DrawGroup:
    """Triangles drawn with one material and one state.

    Attributes
    ----------
    first, count : int, index range (in indices, not triangles) in the index buffer
    material : int
    cull : bool, back faces culled (not double-sided)
    blend : bool, alpha BLEND (drawn after the opaque groups, depth writes off)
    centre : ndarray (3,) float32, mean rest position of its vertices (for sorting blended groups)
    """

    first: int
    count: int
    material: int
    cull: bool
    blend: bool
    centre: np.ndarray


def draw_groups(character: Character, view_dir: np.ndarray,
                cull_back_faces: bool = True) -> tuple[np.ndarray, list[DrawGroup]]:
    """Triangles reordered into draw groups and the groups: opaque culled, opaque double-sided, blended.

    Parameters
    ----------
    character : Character with parts
    view_dir : ndarray (3,), the camera's viewing direction (blended triangles are sorted far to near along it)
    cull_back_faces : bool, False draws every group two-sided

    Returns
    -------
    triangles : ndarray (m, 3) uint32, hidden-kind triangles left out
    groups : list of DrawGroup, opaque ones first; blended ones in their rest order (sort per frame)
    """
    c = character
    look = look_of(c)
    kinds = c.material_params[:, 2].round().astype(int)
    mat = c.triangle_material.astype(np.int64)
    keep = kinds[mat] != MATERIAL_KINDS["hidden"]
    primitive = np.zeros(len(c.triangles), np.int64)
    if c.layout is not None:
        for p, (_, _, first, n, _, _) in enumerate(c.layout.primitives):
            primitive[first:first + n] = p
    double = look.shading[:, 1] > 0.5
    blend = look.alpha[:, 0].round().astype(int) == _BLEND
    pieces, groups, first = [], [], 0
    order = [(False, False), (False, True), (True, None)]  # (blend, double-sided); blended: either
    for want_blend, want_double in order:
        for m in range(len(c.material_names)):
            if bool(blend[m]) != want_blend or (want_double is not None and bool(double[m]) != want_double):
                continue
            sel = keep & (mat == m)
            keys = np.unique(primitive[sel]) if want_blend else [None]
            for key in keys:
                s = sel if key is None else sel & (primitive == key)
                tris = c.triangles[s]
                if not len(tris):
                    continue
                if want_blend:  # far to near along the view direction
                    depth = c.vertices[tris].mean(axis=1) @ np.asarray(view_dir, np.float64)
                    tris = tris[np.argsort(-depth, kind="stable")]
                else:  # compact patches: fewer vertex shader runs (triangle_order)
                    tris = cache_order(tris, c.vertices)
                pieces.append(tris)
                centre = c.vertices[np.unique(tris)].mean(axis=0).astype(np.float32)
                groups.append(DrawGroup(first, 3 * len(tris), m, cull_back_faces and not bool(double[m]),
                                        want_blend, centre))
                first += 3 * len(tris)
    tris = np.ascontiguousarray(np.vstack(pieces) if pieces else np.zeros((0, 3)), dtype=np.uint32)
    return tris, groups


def _slerp_identity(q: np.ndarray, share: float) -> np.ndarray:
    """The rotation ``q`` (x, y, z, w) scaled to ``share`` of its angle about the same axis."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    angle = 2.0 * np.arccos(np.clip(q[3], -1.0, 1.0))
    s = np.sin(angle / 2.0)
    if s < 1e-9:
        return np.array([0.0, 0.0, 0.0, 1.0])
    axis = q[:3] / s
    half = angle * share / 2.0
    return np.r_[axis * np.sin(half), np.cos(half)]


class HeadPose:
    """Skinning matrices for a head rotation through the humanoid head (and neck) bones.

    ``head_rotation`` (x, y, z, w), world frame, is split into ``NECK_SHARE`` of
    its angle about the neck's rest position and the rest about the (carried)
    head position: the head ends turned by the whole rotation, the neck by a
    share, the body not at all. The result equals
    ``Skeleton.pose_matrices({neck: q_neck, head: q_head})`` (tested), computed
    with the node masks cached.

    Attributes
    ----------
    available : bool, the skeleton has a humanoid ``head`` bone
    moved_nodes : ndarray (n_nodes,) bool, the nodes a head pose moves (neck or head and below)
    """

    def __init__(self, character: Character, neck_share: float = NECK_SHARE) -> None:
        sk = character.skeleton
        self.available = sk is not None and "head" in sk.bones
        self.n_nodes = sk.n_nodes if sk is not None else 0
        self._identity = np.tile(np.eye(4, dtype=np.float32), (max(self.n_nodes, 1), 1, 1))
        self.moved_nodes = np.zeros(self.n_nodes, bool)
        if not self.available:
            return
        rest = sk.global_transforms()
        self.head = int(sk.bones["head"])
        self.neck = int(sk.bones["neck"]) if "neck" in sk.bones and neck_share > 0 else None
        self.neck_share = float(neck_share) if self.neck is not None else 0.0
        self._head_mask = sk.descendants(self.head)
        self._head_pivot = rest[self.head][:, 3]
        if self.neck is not None:
            self._neck_mask = sk.descendants(self.neck)
            self._neck_pivot = rest[self.neck][:, 3]
            self.moved_nodes = self._neck_mask | self._head_mask
        else:
            self.moved_nodes = self._head_mask.copy()

    def rotations(self, rotation: np.ndarray) -> dict[int, np.ndarray]:
        """The per-bone quaternions a head ``rotation`` is split into ({node: (x, y, z, w)})."""
        if self.neck is None:
            return {self.head: np.asarray(rotation, np.float64)}
        return {self.neck: _slerp_identity(rotation, self.neck_share),
                self.head: _slerp_identity(rotation, 1.0 - self.neck_share)}

    def matrices(self, rotation: np.ndarray | None) -> np.ndarray:
        """Skinning matrices (n_nodes, 4, 4) float32 (identities for None)."""
        if rotation is None or not self.available:
            return self._identity[:self.n_nodes]
        d = self._identity[:self.n_nodes].astype(np.float64)
        carried = np.eye(4)
        for node, q in sorted(self.rotations(rotation).items()):
            mask = self._neck_mask if node == self.neck else self._head_mask
            pivot = (carried @ (self._neck_pivot if node == self.neck else self._head_pivot))[:3]
            turn = np.eye(4)
            r = quat_to_matrix(q)
            turn[:3, :3] = r
            turn[:3, 3] = pivot - r @ pivot
            d[mask] = turn @ d[mask]
            if node == self.neck:
                carried = turn
        return d.astype(np.float32)


class CpuSkinner:
    """Linear blend skinning in NumPy of the vertices a head pose moves.

    ``x' = (sum_k w_k D_{j_k}) x`` for the vertices with weight on a moved
    node; the others keep their (morphed) rest position.

    Parameters
    ----------
    character : Character with a skeleton
    moved_nodes : ndarray (n_nodes,) bool, the nodes that can move (HeadPose.moved_nodes)
    """

    def __init__(self, character: Character, moved_nodes: np.ndarray) -> None:
        sk = character.skeleton
        nodes = sk.vertex_nodes.astype(np.int64)
        weights = sk.vertex_weights
        touched = (moved_nodes[nodes] & (weights > 0)).any(axis=1)
        self.rows = np.flatnonzero(touched)
        self._nodes = nodes[self.rows]
        self._weights = weights[self.rows].astype(np.float32)
        self._out = np.zeros((character.n_vertices, 6), np.float32)

    def skin(self, deformed: np.ndarray, matrices: np.ndarray | None) -> np.ndarray:
        """Skinned [position, normal] (n, 6) float32 from morphed ``deformed`` (n, 6); ``deformed`` is
        returned as it is when ``matrices`` is None (the rest pose)."""
        if matrices is None or not len(self.rows):
            return deformed
        out = self._out
        np.copyto(out, deformed)
        m = np.einsum("vk,vkij->vij", self._weights, matrices[self._nodes])   # (m, 4, 4) blended
        part = deformed[self.rows]
        rot = m[:, :3, :3]
        out[self.rows, :3] = np.einsum("vij,vj->vi", rot, part[:, :3]) + m[:, :3, 3]
        out[self.rows, 3:] = np.einsum("vij,vj->vi", rot, part[:, 3:])
        return out


def head_vertices(character: Character, threshold: float = 0.5) -> np.ndarray:
    """Vertex indices that follow the humanoid head bone and its descendants (weight >= ``threshold``);
    every vertex for a character without a skeleton or head bone."""
    sk = character.skeleton
    if sk is None or "head" not in sk.bones:
        return np.arange(character.n_vertices)
    mask = sk.descendants(int(sk.bones["head"]))
    w = (sk.vertex_weights * mask[sk.vertex_nodes.astype(np.int64)]).sum(axis=1)
    return np.flatnonzero(w >= threshold)


def joint_texels(matrices: np.ndarray) -> bytes:
    """Skinning matrices (n, 4, 4) row-major as the joint texture's texels: node j's column c at 4j + c."""
    return np.ascontiguousarray(matrices.transpose(0, 2, 1), dtype=np.float32).tobytes()


__all__ = ["NECK_SHARE", "CpuSkinner", "DrawGroup", "HeadPose", "draw_groups", "has_parts", "head_vertices",
           "joint_texels", "look_of", "make_textures", "material_block", "material_model_of", "material_variant",
           "outline_variant", "uv_matrix", "vertex_attributes"]
