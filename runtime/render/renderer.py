"""Draw a character from blendshape weights and a head pose.

Two deformation paths give the same picture:

* ``gpu``: every shape's position and normal deltas sit in one texture (16-bit fixed point);
  per frame only the active (shape, weight) pairs are uploaded as uniforms
  (a few hundred bytes) and the vertex shader sums them.
* ``cpu``: :class:`~facepuppet.runtime.render.cpu_deform.CpuDeformer` sums the same
  deltas with NumPy and the result is written into the vertex buffer.
* ``elastic`` (only when asked, with an elastic table): the vertex shader
  spreads control-point displacements with a compact basis
  (:mod:`~facepuppet.runtime.render.elastic_path`, Yano & Harada 2009).

A character with glTF / VRM parts (a look, a skeleton) is drawn through
``character.glsl`` with textures, the glTF material model, alpha modes and
linear blend skinning (:mod:`~facepuppet.runtime.render.parts_path`) on both
paths; a character without parts through ``face.glsl``, as before.

On a real GPU the first wins by far. On Mesa's software rasteriser the vertex
shader is emulated and the CPU path can be faster, so with ``path="auto"`` the
renderer times both at construction and keeps the faster, saying which.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from facepuppet.runtime.character import MATERIAL_KINDS, Character, moving_vertices
from facepuppet.runtime.geometry import bounds
from facepuppet.runtime.render.camera import frame_bounds, model_matrix
from facepuppet.runtime.render.cpu_deform import CpuDeformer, check_weights
from facepuppet.runtime.render.elastic_path import check_model, setup_elastic, upload_controls
from facepuppet.runtime.render.layers import LAYER_KINDS, has_layers, vertex_opacity
from facepuppet.runtime.render.options import FRAMINGS
from facepuppet.runtime.render.parts_path import (
    CpuSkinner,
    HeadPose,
    draw_groups,
    has_parts,
    head_vertices,
    joint_texels,
    look_of,
    make_textures,
    material_block,
    material_variant,
    variant_defines,
    vertex_attributes,
)
from facepuppet.runtime.render.shader_loader import load_program
from facepuppet.runtime.render.triangle_order import cache_order

if TYPE_CHECKING:
    from facepuppet.runtime.elastic.model import ElasticModel

DELTA_TEXTURE_WIDTH = 4096
MAX_ACTIVE_LIMIT = 256  # uniform array length cap; more active shapes keep the largest weights
PATHS = ("auto", "gpu", "cpu", "elastic")
_JOINT_UNIT, _TEXTURE_UNIT = 2, 3
_HIDDEN = MATERIAL_KINDS["hidden"]
# Thin layers drawn two-sided and blended after the surfaces, in this order (each over the ones before).
_TWO_SIDED = LAYER_KINDS


def realistic_weights(n_shapes: int, n_active: int = 10) -> np.ndarray:
    """A plausible frame: ``n_active`` shapes spread over the set at weights 0.2..0.8, float32."""
    w = np.zeros(n_shapes, dtype=np.float32)
    active = np.unique(np.linspace(0, n_shapes - 1, min(n_active, n_shapes)).astype(int))
    w[active] = np.linspace(0.2, 0.8, len(active), dtype=np.float32)
    return w


def vertex_materials(character: Character) -> np.ndarray:
    """Per-vertex (kind, specular, shininess) from the first triangle using each vertex.

    Returns
    -------
    ndarray of shape (n_vertices, 3), float32; vertices in no triangle get skin.
    """
    params = character.material_params
    per_tri = np.stack(
        [params[:, 2], params[:, 0], params[:, 1]], axis=1
    )[character.triangle_material]
    out = np.tile(np.array([MATERIAL_KINDS["skin"], 0.1, 16.0], np.float32), (character.n_vertices, 1))
    tris = character.triangles.astype(np.int64)
    # Reverse order so the first triangle that names a vertex is the last write.
    out[tris[::-1].reshape(-1)] = np.repeat(per_tri[::-1], 3, axis=0)
    return out.astype(np.float32)


def visible_triangles(character: Character) -> tuple[np.ndarray, int]:
    """Triangles not of kind ``hidden``, one-sided kinds first (by material, each in compact patches:
    :mod:`~facepuppet.runtime.render.triangle_order`), then the thin layers in ``_TWO_SIDED`` order.

    Returns
    -------
    triangles : ndarray of shape (m, 3), uint32
    n_one_sided : int, the first ``n_one_sided`` rows may be back-face culled;
        the rest (thin cards such as lashes) are seen from both sides.
    """
    kinds = character.material_params[:, 2].round().astype(int)[character.triangle_material]
    keep = (kinds != _HIDDEN) & ~np.isin(kinds, _TWO_SIDED)
    # material by material in file order (the face before what it hides), each in compact patches
    one_sided = np.vstack([np.zeros((0, 3), np.uint32)] + [
        cache_order(character.triangles[keep & (character.triangle_material == m)], character.vertices)
        for m in range(len(character.material_names))])
    two_sided = [character.triangles[kinds == k] for k in _TWO_SIDED]
    tris = np.ascontiguousarray(np.vstack([one_sided, *two_sided]), dtype=np.uint32)
    return tris, len(one_sided)


def gpu_defines(character: Character) -> dict:
    """The #defines of face.glsl's GPU deformation variant for ``character``."""
    return {
        "GPU_DEFORM": 1,
        "MAX_ACTIVE": max(1, min(character.n_shapes, MAX_ACTIVE_LIMIT)),
        "N_VERTICES": character.n_vertices,
        "DELTA_TEXTURE_WIDTH": DELTA_TEXTURE_WIDTH,
    }


#: Steps of a delta component either side of zero (16-bit offsets; blendshapes.glsl)
DELTA_STEPS = 32767


def delta_steps(character: Character) -> np.ndarray:
    """Per shape, the size of one step of its position and of its normal deltas (n_shapes, 2), float64.

    A step is the shape's largest |component| of that kind over ``DELTA_STEPS`` (0 for a shape
    that moves nothing of the kind), so each delta component is within half a step of its 16-bit
    value: at most 1/65534 of the shape's largest.
    """
    c = character
    steps = np.zeros((c.n_shapes, 2))
    for s in range(c.n_shapes):
        sl = c.shape_slice(s)
        for k, src in enumerate((c.delta_positions, c.delta_normals)):
            if sl.stop > sl.start:
                steps[s, k] = float(np.abs(src[sl]).max()) / DELTA_STEPS
    return steps


def delta_offsets(character: Character) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every stored delta component as its 16-bit offset from zero, in steps of its shape (:func:`delta_steps`).

    Returns
    -------
    positions, normals : ndarray of shape (len(delta_indices), 3), int32, in [-32767, 32767], row for row
        with ``delta_positions`` / ``delta_normals``
    steps : ndarray of shape (n_shapes, 2), float64
    """
    c = character
    steps = delta_steps(c)
    out = []
    for k, src in enumerate((c.delta_positions, c.delta_normals)):
        q = np.zeros(src.shape, np.int32)
        for s in range(c.n_shapes):
            sl = c.shape_slice(s)
            if steps[s, k] > 0:
                q[sl] = np.rint(src[sl] / steps[s, k])
        out.append(q)
    return out[0], out[1], steps


def on_delta_grid(character: Character) -> Character:
    """``character`` with every delta component on its shape's 16-bit grid (:func:`delta_offsets`), as the
    gpu path's texture holds them: the cpu path draws these, so both paths draw the same surface (with the
    file's deltas a vertex moved up to 1/65534 of its shape's largest delta apart, and where that moved an
    edge across a pixel's centre the two paths' pictures differed by that pixel)."""
    import dataclasses

    c = character
    q_pos, q_nrm, steps = delta_offsets(c)
    step_of_row = np.repeat(steps, np.diff(c.delta_offsets), axis=0)  # (len(delta_indices), 2)
    return dataclasses.replace(c, delta_positions=(q_pos * step_of_row[:, :1]).astype(np.float32),
                               delta_normals=(q_nrm * step_of_row[:, 1:]).astype(np.float32))


def delta_texture(ctx: moderngl.Context, character: Character) -> tuple[moderngl.Texture, np.ndarray]:
    """Position and normal deltas of every shape in one RGB32UI texture of width DELTA_TEXTURE_WIDTH.

    Texel ``shape * n_vertices + vertex`` holds that shape's six delta components (position x y z,
    normal x y z) as 16-bit offsets ``q + 32768`` (:func:`delta_offsets`), two per word, low half first;
    32768 (exactly zero) where the shape does not move the vertex. One fetch per active shape and
    vertex where two float textures took two: on llvmpipe the fetches are the whole cost of the
    vertex shader's sum (the ICT head, 10 shapes active: 6.4 ms of the vertex stage with two
    RGB32F fetches, the loop without fetches nothing), and the texture is half the size.

    Returns
    -------
    texture : moderngl.Texture, RGB32UI, nearest
    steps : ndarray of shape (n_shapes, 2), float32, :func:`delta_steps` (what a weight is multiplied by)
    """
    c = character
    n = c.n_vertices
    q_pos, q_nrm, steps = delta_offsets(c)
    rows = max(1, -(-(c.n_shapes * n) // DELTA_TEXTURE_WIDTH))
    texels = np.full((rows * DELTA_TEXTURE_WIDTH, 6), 32768, dtype=np.uint16)
    shape_of_row = np.repeat(np.arange(c.n_shapes), np.diff(c.delta_offsets))
    texel = shape_of_row * n + c.delta_indices.astype(np.int64)
    texels[texel] = np.hstack([q_pos, q_nrm]) + 32768
    # little-endian uint16 pairs read as uint32: the first of each pair is the low half
    tex = ctx.texture((DELTA_TEXTURE_WIDTH, rows), 3, texels.astype("<u2").tobytes(), dtype="u4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex, steps.astype(np.float32)


def active_uniforms(weights: np.ndarray, steps: np.ndarray, max_active: int) -> tuple[int, np.ndarray, np.ndarray]:
    """The active shapes of a frame as blendshapes.glsl takes them.

    At most ``max_active`` non-zero weights (the largest in magnitude when there are more).

    Returns
    -------
    count : int
    shapes : ndarray of shape (max_active,), int32, the first ``count`` used
    weights : ndarray of shape (max_active, 2), float32, weight times the shape's (position, normal) step
    """
    w = np.asarray(weights, np.float32)
    active = np.flatnonzero(w)
    if len(active) > max_active:
        keep = np.argsort(-np.abs(w[active]), kind="stable")[:max_active]
        active = np.sort(active[keep])
    count = len(active)
    shapes = np.zeros(max_active, np.int32)
    scaled = np.zeros((max_active, 2), np.float32)
    shapes[:count] = active
    scaled[:count] = w[active, None] * steps[active]
    return count, shapes, scaled


class FaceRenderer:
    """Renders a character into an offscreen framebuffer (or a window's).

    Parameters
    ----------
    ctx : moderngl.Context
    character : Character
    width, height : int, pixels
    path : {"auto", "gpu", "cpu", "elastic"}, deformation path; "auto" measures gpu and cpu and keeps the faster
    target_fbo : moderngl.Framebuffer or None; None renders offscreen (read back with read_pixels)
    background : tuple of 3 float, display RGB 0..1
    transparent : bool, clear to alpha 0: :meth:`read_pixels` gives RGBA (straight alpha, alpha 0 where
        nothing is drawn); blending keeps alpha right (separate alpha blend function)
    credits : str or None, a line drawn in the bottom-left corner over every frame (the attribution a
        licence asks for, ``Character.credits``); None or "" draws nothing
    msaa : int, samples of the offscreen framebuffer (0 or 1: none; capped at the context's maximum);
        a window's samples are the window's (``create_context(samples=...)``)
    log : callable(str), receives the one-line path report
    cull_back_faces : bool
        Cull back faces of closed, consistently wound surfaces (about half the
        triangles of a head; a large saving on a software rasteriser). Thin
        cards (lashes) are always drawn two-sided, and lighting is two-sided.
    framing : str, "body" (fit every drawn vertex), "head" (the vertices following the
        humanoid head bone; every drawn vertex for a character without a skeleton) or "face"
        (the vertices the expressions move, so a contact sheet shows them large)
    elastic : ElasticModel or None, compact basis and parameters; required for (and only used by) "elastic"

    Attributes
    ----------
    path : str, "gpu" or "cpu"
    path_report : str
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        character: Character,
        width: int = 1280,
        height: int = 720,
        path: str = "auto",
        target_fbo: moderngl.Framebuffer | None = None,
        background: tuple[float, float, float] = (0.16, 0.17, 0.19),
        log: Callable[[str], None] = print,
        cull_back_faces: bool = True,
        framing: str = "head",
        elastic: ElasticModel | None = None,
        transparent: bool = False,
        msaa: int = 0,
        credits: str | None = None,
    ) -> None:
        if framing not in FRAMINGS:
            raise ValueError(f"framing: expected one of {FRAMINGS}, got {framing!r}")
        self.framing = framing
        if path not in PATHS:
            raise ValueError(f"path: expected one of {PATHS}, got {path!r}")
        if width <= 0 or height <= 0:
            raise ValueError(f"width, height: expected positive pixels, got {width}x{height}")
        self.ctx = ctx
        self.character = character
        self.width, self.height = int(width), int(height)
        self.background = tuple(float(c) for c in background)
        self.transparent = bool(transparent)
        if int(msaa) < 0:
            raise ValueError(f"msaa: expected 0 (off) or a sample count, got {msaa}")
        self.samples = min(int(msaa), int(ctx.max_samples)) if int(msaa) > 1 and target_fbo is None else 0
        self.parts = has_parts(character)
        if self.parts and path == "elastic":
            raise ValueError("path: the elastic path draws characters without a skeleton or look only")
        self._head_pose = HeadPose(character) if self.parts else None
        self.cull_back_faces = bool(cull_back_faces)
        self._own_fbo = target_fbo is None
        # Bound again on close, so that no deleted framebuffer stays bound.
        self._previous_fbo = ctx.fbo or ctx.detect_framebuffer(0)
        self._resolve = None
        if target_fbo is None:
            size = (self.width, self.height)
            self._color = ctx.renderbuffer(size, 4, samples=self.samples)
            self._depth = ctx.depth_renderbuffer(size, samples=self.samples)
            self.fbo = ctx.framebuffer(self._color, self._depth)
            if self.samples:  # multisampled: resolved into a plain one before reading
                self._resolve_color = ctx.renderbuffer(size, 4)
                self._resolve = ctx.framebuffer(self._resolve_color)
        else:
            self.fbo = target_fbo
        self._setup_camera()
        self._setup_buffers()
        self._gpu = self._cpu = self._elastic = None
        self._look = look_of(character) if self.parts else None
        self._textures = make_textures(ctx, self._look) if self.parts else []
        self._materials = [ctx.buffer(material_block(character, m)) for m in range(len(character.material_names))] \
            if self.parts else []
        if path == "elastic":
            if elastic is None:
                raise ValueError("elastic: path 'elastic' needs an ElasticModel (elastic=...)")
            self._elastic = setup_elastic(ctx, character, check_model(character, elastic), self._vao)
        if path in ("auto", "gpu"):
            self._gpu = self._setup_gpu()
        if path in ("auto", "cpu"):
            self._cpu = self._setup_cpu()
        self._pose = np.eye(4, dtype=np.float32)
        self._label = self._setup_label(credits) if credits else None
        if path == "auto":
            self.path, self.path_report = self._choose_path()
            log(self.path_report)
        else:
            self.path = path
            self.path_report = f"deformation path: {path} (asked for)"

    # -- construction ------------------------------------------------------
    def _setup_camera(self) -> None:
        c = self.character
        kinds = c.material_params[:, 2].round().astype(int)
        tris = c.triangles[kinds[c.triangle_material] != _HIDDEN]
        used = np.unique(tris) if len(tris) else np.arange(c.n_vertices)
        if self.framing == "head":  # the head bone and below; a character without a skeleton is a head
            head = np.intersect1d(used, head_vertices(c))
            used = head if len(head) else used
        elif self.framing == "face":  # the part the shapes move; a character nothing moves is framed whole
            moving = moving_vertices(c)
            used = np.intersect1d(used, moving) if len(moving) else used
        lo, hi = bounds(c.vertices[used])
        whole_lo, whole_hi = bounds(c.vertices[np.unique(tris)] if len(tris) else c.vertices)
        if float(np.max(hi - lo)) <= 0.05 * float(np.max(whole_hi - whole_lo)):
            # a head or face part too small to frame (one moving vertex, a degenerate head box): frame it all
            lo, hi = whole_lo, whole_hi
        self.camera = frame_bounds(lo, hi, self.width / self.height)

    def _setup_buffers(self) -> None:
        c, ctx = self.character, self.ctx
        if self.parts:
            # the thin layers of an OBJ rig (kinds kept through glTF) fade as on the OBJ path
            self._attr_vbo = ctx.buffer(vertex_attributes(c, vertex_opacity(c) if has_layers(c) else None).tobytes())
            view_dir = self.camera.view[2, :3] * -1.0  # the camera looks along -z of its frame
            tris, self._groups = draw_groups(c, view_dir, self.cull_back_faces)
            self._variant_of = [material_variant(c, m) for m in range(len(c.material_names))]
            self._ibo = ctx.buffer(tris.tobytes() if len(tris) else b"\0" * 12)
            self.n_indices = len(tris) * 3
            self.n_one_sided_indices = 0
            return
        attrs = np.hstack([c.vertex_color, vertex_materials(c), vertex_opacity(c)[:, None]]).astype(np.float32)
        self._attr_vbo = ctx.buffer(attrs.tobytes())
        tris, n_one_sided = visible_triangles(c)
        self._ibo = ctx.buffer(tris.tobytes())
        self.n_indices = len(tris) * 3
        self.n_one_sided_indices = n_one_sided * 3 if self.cull_back_faces else 0

    def _setup_gpu(self) -> dict:
        c, ctx = self.character, self.ctx
        defines = gpu_defines(c)
        max_active = defines["MAX_ACTIVE"]
        skin = self.parts and c.skeleton is not None
        if skin:
            defines["SKIN"] = 1
        deltas, steps = delta_texture(ctx, c)
        rest = np.hstack([c.vertices, c.rest_normals()]).astype(np.float32)
        vbo = ctx.buffer(rest.tobytes())
        programs, vaos = self._programs(defines, vbo)
        joints = None
        if skin:
            n_nodes = c.skeleton.n_nodes
            joints = ctx.texture((4 * n_nodes, 1), 4, joint_texels(np.tile(np.eye(4), (n_nodes, 1, 1))), dtype="f4")
            joints.filter = (moderngl.NEAREST, moderngl.NEAREST)
        for prog in programs.values():  # an unlit variant does not read the normals
            for name, unit in (("u_deltas", 0), ("u_joints", _JOINT_UNIT)):
                if name in prog:
                    prog[name].value = unit
        return {
            "joints": joints,
            "programs": programs,
            "vaos": vaos,
            "vbo": vbo,
            "textures": [deltas],
            "steps": steps,
            "max_active": max_active,
        }

    def _setup_cpu(self) -> dict:
        deformer = CpuDeformer(on_delta_grid(self.character))  # the deltas the gpu path draws
        vbo = self.ctx.buffer(deformer.rest.tobytes(), dynamic=True)
        programs, vaos = self._programs({}, vbo)
        skinner = None
        if self.parts and self._head_pose.available:
            skinner = CpuSkinner(self.character, self._head_pose.moved_nodes)
        return {"programs": programs, "vaos": vaos, "vbo": vbo, "deformer": deformer, "skinner": skinner}

    def _programs(self, defines: dict, vbo) -> tuple[dict, dict]:
        """The programs and vertex arrays of one deformation path, by fragment variant.

        A character without parts has one (``face.glsl``, key None); a character with parts one
        ``character.glsl`` program per distinct :func:`material_variant` of its draw groups.
        """
        if not self.parts:
            prog = load_program(self.ctx, "face.glsl", defines or None)
            return {None: prog}, {None: self._vao(prog, vbo)}
        programs, vaos = {}, {}
        for key in dict.fromkeys(self._variant_of[g.material] for g in self._groups) or [(0, 0, 0, 0, 0)]:
            prog = load_program(self.ctx, "character.glsl", {**defines, **variant_defines(key)})
            self._bind_parts(prog)
            programs[key], vaos[key] = prog, self._vao(prog, vbo)
        return programs, vaos

    def _setup_label(self, text: str) -> dict:
        """The credits label: a Pillow-rendered RGBA texture on a quad in the bottom-left corner."""
        from facepuppet.runtime.render.images import label_image

        ctx = self.ctx
        image = label_image(text, scale=2 if self.height >= 600 else 1)
        h, w = image.shape[:2]
        tex = ctx.texture((w, h), 4, np.ascontiguousarray(image[::-1]).tobytes())  # GL rows bottom first
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        margin = 8
        x0, y0 = -1 + 2 * margin / self.width, -1 + 2 * margin / self.height
        x1, y1 = x0 + 2 * w / self.width, y0 + 2 * h / self.height
        quad = np.array([[x0, y0, 0, 0], [x1, y0, 1, 0], [x1, y1, 1, 1], [x0, y1, 0, 1]], np.float32)
        prog = load_program(ctx, "text_overlay.glsl")
        vbo = ctx.buffer(quad.tobytes())
        ibo = ctx.buffer(np.array([0, 1, 2, 0, 2, 3], np.uint32).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "2f 2f", "in_position", "in_uv")], index_buffer=ibo,
                               index_element_size=4)
        return {"prog": prog, "vbo": vbo, "ibo": ibo, "vao": vao, "texture": tex, "size": (w, h)}

    def _draw_label(self) -> None:
        label = self._label
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.enable(moderngl.BLEND)
        label["texture"].use(0)
        label["prog"]["u_label"].value = 0
        label["vao"].render(moderngl.TRIANGLES)
        self.ctx.disable(moderngl.BLEND)
        self.ctx.enable(moderngl.DEPTH_TEST)

    def _bind_parts(self, prog) -> None:
        prog["Material"].binding = 0
        if "u_base_texture" in prog:
            prog["u_base_texture"].value = _TEXTURE_UNIT

    def _vao(self, prog, vbo):
        """The vertex array of ``prog``; attributes a variant does not read are skipped (padding)."""
        def layout(buffer, attributes):  # [(name, floats)] -> (buffer, format, *names present)
            fmt = " ".join(f"{k}f" if name in prog else f"{4 * k}x" for name, k in attributes)
            return (buffer, fmt, *(name for name, _ in attributes if name in prog))

        if self.parts:  # colour 3, uv 2, joints 4, weights 4; without SKIN the joints are skipped
            attributes = [("in_color", 3), ("in_uv", 2), ("in_joints", 4), ("in_weights", 4), ("in_opacity", 1)]
        else:
            attributes = [("in_color", 3), ("in_material", 3), ("in_opacity", 1)]
        return self.ctx.vertex_array(
            prog, [layout(vbo, [("in_position", 3), ("in_normal", 3)]), layout(self._attr_vbo, attributes)],
            index_buffer=self._ibo, index_element_size=4,
        )

    def _choose_path(self, warmup: int = 2, frames: int = 10) -> tuple[str, str]:
        """Time both paths (draw + finish per frame) and return (faster, report line).

        Frames of the two paths alternate, so that a burst of load from
        elsewhere on the machine falls on both rather than on one.
        """
        # A live tracker keeps nearly every channel slightly non-zero, and both
        # paths cost more per active shape: time them with every shape active.
        weights = realistic_weights(self.character.n_shapes, n_active=self.character.n_shapes)
        times: dict[str, list[float]] = {"gpu": [], "cpu": []}
        for i in range(warmup + frames):
            for path in ("gpu", "cpu"):
                self.path = path
                t0 = time.perf_counter()
                self.draw(weights)
                self.finish()
                if i >= warmup:
                    times[path].append(time.perf_counter() - t0)
        medians = {path: float(np.median(t)) * 1e3 for path, t in times.items()}
        best = min(medians, key=medians.get)
        other = "cpu" if best == "gpu" else "gpu"
        report = (
            f"deformation path: {best} ({best} {medians[best]:.1f} ms, {other} {medians[other]:.1f} ms "
            f"median per frame over {frames} frames at {self.width}x{self.height})"
        )
        return best, report

    # -- per frame ---------------------------------------------------------
    def prepare(self, weights: np.ndarray, head_rotation: np.ndarray | None = None,
                head_translation: np.ndarray | None = None) -> None:
        """The CPU side of a frame: pose, active weights or CPU deformation, uploads."""
        w = check_weights(weights, self.character.n_shapes)
        joints = None
        if self.parts and self._head_pose.available:  # the head turns through the skeleton, the body stays
            self._pose = model_matrix(None, head_translation)
            joints = self._head_pose.matrices(head_rotation) if head_rotation is not None else None
        else:
            self._pose = model_matrix(head_rotation, head_translation, self.character.pivot)
        if self.path == "gpu":
            self._upload_active(w)
            tex = self._gpu["joints"]
            if tex is not None:
                tex.write(joint_texels(joints if joints is not None else self._head_pose.matrices(None)))
        elif self.path == "elastic":
            upload_controls(self._elastic, self._elastic["model"].blend(w))  # Yano & Harada eq. 7
        else:
            cpu = self._cpu
            out = cpu["deformer"].deform_into(w)
            if cpu["skinner"] is not None:
                out = cpu["skinner"].skin(out, joints)
            cpu["vbo"].orphan()
            cpu["vbo"].write(out)

    def prepare_controls(self, controls: np.ndarray, head_rotation: np.ndarray | None = None,
                         head_translation: np.ndarray | None = None) -> None:
        """The CPU side of an elastic frame from control displacements, (n_controls, 3) float32."""
        if self.path != "elastic":
            raise ValueError("prepare_controls: only the 'elastic' path takes control displacements "
                             f"(path is {self.path!r})")
        self._pose = model_matrix(head_rotation, head_translation, self.character.pivot)
        upload_controls(self._elastic, controls)

    def _upload_active(self, w: np.ndarray) -> None:
        gpu = self._gpu
        count, shapes, weights = active_uniforms(w, gpu["steps"], gpu["max_active"])
        shapes, weights = shapes.tobytes(), weights.tobytes()
        for prog in gpu["programs"].values():
            prog["u_active_count"].value = count
            if count:
                prog["u_active_shape"].write(shapes)
                prog["u_active_weight"].write(weights)

    def submit(self) -> None:
        """Issue the draw call for the prepared frame (never waits for the GPU)."""
        state = {"gpu": self._gpu, "cpu": self._cpu, "elastic": self._elastic}[self.path]
        model, view_projection = self._pose.T.tobytes(), self.camera.view_projection.T.tobytes()
        eye = tuple(float(x) for x in self.camera.eye)
        for prog in state["programs"].values():
            prog["u_model"].write(model)
            prog["u_view_projection"].write(view_projection)
            if "u_eye" in prog:  # an unlit or toon variant does not read it
                prog["u_eye"].value = eye
        if self.path in ("gpu", "elastic"):
            for unit, tex in enumerate(state["textures"]):
                tex.use(unit)
            if state.get("joints") is not None:
                state["joints"].use(_JOINT_UNIT)
        self.fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.fbo.clear(*((0.0, 0.0, 0.0, 0.0) if self.transparent else (*self.background, 1.0)), depth=1.0)
        # Straight colour over, alpha accumulated as coverage: alpha stays right over a transparent clear.
        self.ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,
                               moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        if self.parts:
            self._submit_groups(state["vaos"])
        else:
            self._submit_kinds(state)
        if self._label is not None:
            self._draw_label()

    def _submit_kinds(self, state: dict) -> None:
        """A character without parts: one-sided kinds culled, then two-sided cards (lashes) blended."""
        culled = self.n_one_sided_indices
        if culled:
            self.ctx.front_face = "ccw"
            self.ctx.enable(moderngl.CULL_FACE)
            state["vaos"][None].render(moderngl.TRIANGLES, vertices=culled)
        self.ctx.disable(moderngl.CULL_FACE)
        if self.n_indices > culled:
            # Thin two-sided layers (eye occlusion, films, lashes) last, blended over the finished surfaces,
            # without writing depth so that each shows through the ones drawn after it.
            self.ctx.enable(moderngl.BLEND)
            self.fbo.depth_mask = False
            state["vaos"][None].render(moderngl.TRIANGLES, vertices=self.n_indices - culled, first=culled)
            self.fbo.depth_mask = True
            self.ctx.disable(moderngl.BLEND)

    def _submit_groups(self, vaos: dict) -> None:
        """Draw groups: opaque (culled, then double-sided), then blended ones far to near, depth writes off."""
        ctx, groups = self.ctx, self._groups
        blended = [g for g in groups if g.blend]
        if len(blended) > 1:  # per frame: a handful of group centres
            eye = self.camera.eye - self._pose[:3, 3]
            blended.sort(key=lambda g: -float(np.dot(g.centre - eye, g.centre - eye)))
        ctx.front_face = "ccw"
        culling = None
        look, variants = self._look, self._variant_of
        for g in [g for g in groups if not g.blend] + blended:
            if g.cull != culling:
                (ctx.enable if g.cull else ctx.disable)(moderngl.CULL_FACE)
                culling = g.cull
            if g.blend:
                ctx.enable(moderngl.BLEND)
                self.fbo.depth_mask = False
            self._materials[g.material].bind_to_uniform_block(0)
            t = int(look.texture[g.material])
            if t >= 0:
                self._textures[t].use(_TEXTURE_UNIT)
            vaos[variants[g.material]].render(moderngl.TRIANGLES, vertices=g.count, first=g.first)
        ctx.disable(moderngl.CULL_FACE)
        ctx.disable(moderngl.BLEND)
        self.fbo.depth_mask = True

    def draw(self, weights: np.ndarray, head_rotation: np.ndarray | None = None,
             head_translation: np.ndarray | None = None) -> None:
        """Render one frame.

        Parameters
        ----------
        weights : ndarray of shape (n_shapes,), float32, in character shape order
        head_rotation : array_like of shape (4,), quaternion (x, y, z, w) about character.pivot, or None
        head_translation : array_like of shape (3,), character units, or None
        """
        self.prepare(weights, head_rotation, head_translation)
        self.submit()

    def finish(self) -> None:
        """Wait until the GPU has finished the submitted frames."""
        self.ctx.finish()

    def read_pixels(self) -> np.ndarray:
        """The last frame as ndarray of shape (height, width, 3), uint8, top row first; (height, width, 4)
        RGBA with straight (not premultiplied) colour when the background is transparent."""
        fbo = self.fbo
        if self._resolve is not None:
            self.ctx.copy_framebuffer(self._resolve, self.fbo)
            fbo = self._resolve
        k = 4 if self.transparent else 3
        data = fbo.read(viewport=(0, 0, self.width, self.height), components=k, alignment=1)
        image = np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width, k)[::-1].copy()
        if self.transparent:  # the framebuffer holds colour x alpha over the clear (0, 0, 0, 0)
            a = image[:, :, 3:4].astype(np.uint16)
            part = (a > 0) & (a < 255)
            straight = np.minimum((image[:, :, :3].astype(np.uint32) * 255 + a // 2) // np.maximum(a, 1), 255)
            image[:, :, :3] = np.where(part, straight, image[:, :, :3]).astype(np.uint8)
        return image

    def project(self, points: np.ndarray, head_rotation: np.ndarray | None = None,
                head_translation: np.ndarray | None = None) -> np.ndarray:
        """Pixel coordinates (x right, y down) of character-space points, (n, 2) float64.

        The pose is the renderer's model matrix: for a character whose skeleton turns the head
        (a humanoid head bone) only ``head_translation`` applies; the points are not skinned."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.parts and self._head_pose.available:  # the skeleton turns the head, not the whole character
            head_rotation = None
        m = self.camera.view_projection @ model_matrix(head_rotation, head_translation, self.character.pivot)
        clip = np.c_[p, np.ones(len(p))] @ m.T.astype(np.float64)
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) / 2 * self.width, (1 - ndc[:, 1]) / 2 * self.height]

    def close(self) -> None:
        """Release every GL object this renderer made."""
        for state in (self._gpu, self._cpu, self._elastic):
            if state:
                for obj in (*state["vaos"].values(), *state["programs"].values(), state["vbo"]):
                    obj.release()
                for tex in state.get("textures", ()):
                    tex.release()
                if state.get("joints") is not None:
                    state["joints"].release()
        for obj in self._textures + self._materials:
            obj.release()
        if self._label is not None:
            for obj in self._label.values():
                if hasattr(obj, "release"):
                    obj.release()
        self._attr_vbo.release()
        self._ibo.release()
        if self._own_fbo:
            self._previous_fbo.use()
            self.fbo.release()
            self._color.release()
            self._depth.release()
            if self._resolve is not None:
                self._resolve.release()
                self._resolve_color.release()
