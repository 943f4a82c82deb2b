"""Draw a character from blendshape weights and a head pose.

:class:`FaceRenderer` owns what every frame needs whichever way the mesh is deformed: the
camera, the framebuffers (multisampled, resolved before reading), the attribute and index
buffers, the programs' construction, the materials and textures of a character with parts,
the credits label, and the draw passes. The deformation itself is one path object
(:mod:`~facepuppet.runtime.render.paths`: ``gpu``, ``cpu`` or ``elastic``), chosen at
construction; all paths give the same picture.

A character with glTF / VRM parts (a look, a skeleton) is drawn through ``character.glsl``
with textures, the glTF material model, alpha modes and linear blend skinning
(:mod:`~facepuppet.runtime.render.parts_path`) on both the gpu and the cpu path; a character
without parts through ``face.glsl`` (:mod:`~facepuppet.runtime.render.face_mesh`).

On a real GPU the gpu path wins by far. On Mesa's software rasteriser the vertex shader is
emulated and the cpu path can be faster, so with ``path="auto"`` the renderer times both at
construction and keeps the faster, saying which.

A frame is :meth:`FaceRenderer.prepare` (CPU side), :meth:`FaceRenderer.submit` (the draw
passes: clear, surfaces, thin layers or blended groups, label), :meth:`FaceRenderer.finish`,
and :meth:`FaceRenderer.read_pixels` (MSAA resolve, then read back).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import moderngl
import numpy as np

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.camera import model_matrix
from facepuppet.runtime.render.cpu_deform import check_weights
from facepuppet.runtime.render.credits_label import CreditsLabel
from facepuppet.runtime.render.face_mesh import vertex_materials, visible_triangles
from facepuppet.runtime.render.framebuffers import Framebuffers
from facepuppet.runtime.render.framing import frame_character
from facepuppet.runtime.render.layers import SUBTLE_LAYER_KINDS, has_layers, vertex_opacity
from facepuppet.runtime.render.options import FRAMINGS
from facepuppet.runtime.render.parts_path import (
    HeadPose,
    draw_groups,
    has_parts,
    look_of,
    make_textures,
    material_block,
    material_variant,
    variant_defines,
    vertex_attributes,
)
from facepuppet.runtime.render.pass_clock import NO_CLOCK, NoClock, PassClock
from facepuppet.runtime.render.paths.base import PATH_TEXTURE_UNITS, DeformationPath
from facepuppet.runtime.render.paths.cpu import CpuPath
from facepuppet.runtime.render.paths.elastic import ElasticPath
from facepuppet.runtime.render.paths.gpu import GpuPath
from facepuppet.runtime.render.readback import straighten
from facepuppet.runtime.render.shader_loader import load_program
from facepuppet.runtime.render.skeleton_motion import SkeletonMotion

logger = logging.getLogger(__name__)

PATHS = ("auto", "gpu", "cpu", "elastic")
BASE_TEXTURE_UNIT = PATH_TEXTURE_UNITS  # a material's base colour texture, above the path's units


def realistic_weights(n_shapes: int, n_active: int = 10) -> np.ndarray:
    """A plausible frame: ``n_active`` shapes spread over the set at weights 0.2..0.8, float32."""
    w = np.zeros(n_shapes, dtype=np.float32)
    active = np.unique(np.linspace(0, n_shapes - 1, min(n_active, n_shapes)).astype(int))
    w[active] = np.linspace(0.2, 0.8, len(active), dtype=np.float32)
    return w


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
    subtle_layers : bool, draw the subtle see-through eye layers (lid shadow, wet films:
        :data:`~facepuppet.runtime.render.layers.SUBTLE_LAYER_KINDS`); False leaves them out where a frame
        budget asks (:mod:`~facepuppet.runtime.render.quality`); the lashes are always drawn
    springs : bool, simulate the character's spring bones (VRM secondary animation); False leaves them rigid
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
    path : str, "gpu", "cpu" or "elastic"
    path_report : str
    fbo : moderngl.Framebuffer, drawn into (``target_fbo`` or the own one)
    samples : int, multisamples of the own framebuffer (0: none)
    camera : Camera, framed once at construction
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
        log: Callable[[str], None] = logger.info,
        cull_back_faces: bool = True,
        framing: str = "head",
        elastic: ElasticModel | None = None,
        transparent: bool = False,
        msaa: int = 0,
        credits: str | None = None,
        subtle_layers: bool = True,
        springs: bool = True,
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
            raise UsageError("path: the elastic path draws characters without a skeleton or look only")
        self._head_pose = HeadPose(character) if self.parts else None
        self._motion = None  # look-at and spring bones after the head pose (skinned characters with a head bone)
        if self.parts and self._head_pose.available:
            motion = SkeletonMotion(character, self._head_pose, springs=springs)
            if motion.active:
                self._motion = motion
                self._head_pose.moved_nodes = motion.moved_nodes  # the CPU skinner skins what the motion moves
        self.cull_back_faces = bool(cull_back_faces)
        self.subtle_layers = bool(subtle_layers)
        self._framebuffers = Framebuffers(ctx, (self.width, self.height), self.samples, target_fbo)
        self.fbo = self._framebuffers.fbo
        self.camera = frame_character(character, framing, self.width / self.height)
        self._setup_buffers()
        self._look = look_of(character) if self.parts else None
        self._textures = make_textures(ctx, self._look) if self.parts else []
        self._materials = [ctx.buffer(material_block(character, m)) for m in range(len(character.material_names))] \
            if self.parts else []
        if path == "elastic" and elastic is None:
            raise ValueError("elastic: path 'elastic' needs an ElasticModel (elastic=...)")
        candidates = [self._make_path(name, elastic) for name in (("gpu", "cpu") if path == "auto" else (path,))]
        self._pose = np.eye(4, dtype=np.float32)
        self._label = CreditsLabel(ctx, credits, self.width, self.height) if credits else None
        if path == "auto":
            self._deformation, self.path_report = self._choose_path(candidates)
            log(self.path_report)
            for other in candidates:  # the slower path is never drawn again
                if other is not self._deformation:
                    other.release()
        else:
            self._deformation = candidates[0]
            self.path_report = f"deformation path: {path} (asked for)"

    @property
    def path(self) -> str:
        """The deformation path drawing: "gpu", "cpu" or "elastic"."""
        return self._deformation.name

    # -- construction ------------------------------------------------------
    def _setup_buffers(self) -> None:
        """The vertex attributes every path shares (colour, material or uv/skin, opacity) and the index buffer."""
        c, ctx = self.character, self.ctx
        if self.parts:
            # the thin layers of an OBJ rig (kinds kept through glTF) fade as on the OBJ path
            self._attr_vbo = ctx.buffer(vertex_attributes(c, vertex_opacity(c) if has_layers(c) else None).tobytes())
            view_dir = self.camera.view[2, :3] * -1.0  # the camera looks along -z of its frame
            tris, self._groups = draw_groups(c, view_dir, self.cull_back_faces)
            if not self.subtle_layers:
                subtle = np.isin(c.material_params[:, 2].round().astype(int), SUBTLE_LAYER_KINDS)
                self._groups = [g for g in self._groups if not subtle[g.material]]
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
        self._n_surface_indices = n_one_sided * 3
        # the layers follow the surfaces in LAYER_KINDS order, the subtle ones first: leaving them out is
        # starting the layers' draw after them
        self._first_layer_index = self._n_surface_indices
        if not self.subtle_layers:
            kinds = c.material_params[:, 2].round().astype(int)[c.triangle_material]
            self._first_layer_index += 3 * int(np.isin(kinds, SUBTLE_LAYER_KINDS).sum())

    def _make_path(self, name: str, elastic: ElasticModel | None) -> DeformationPath:
        if name == "gpu":
            skin = self.parts and self.character.skeleton is not None
            return GpuPath(self.ctx, self.character, self._programs, skin)
        if name == "cpu":
            return CpuPath(self.ctx, self.character, self._programs, self._head_pose)
        return ElasticPath(self.ctx, self.character, elastic, self._programs)

    def _programs(self, defines: dict, vbo: moderngl.Buffer) -> tuple[dict, dict]:
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
            prog["Material"].binding = 0
            if "u_base_texture" in prog:
                prog["u_base_texture"].value = BASE_TEXTURE_UNIT
            programs[key], vaos[key] = prog, self._vao(prog, vbo)
        return programs, vaos

    def _vao(self, prog: moderngl.Program, vbo: moderngl.Buffer) -> moderngl.VertexArray:
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

    def _choose_path(self, candidates: list[DeformationPath], warmup: int = 2,
                     frames: int = 10) -> tuple[DeformationPath, str]:
        """Time the gpu and cpu paths (draw + finish per frame) and return (faster, report line).

        Frames of the two paths alternate, so that a burst of load from
        elsewhere on the machine falls on both rather than on one.
        """
        # A live tracker keeps nearly every channel slightly non-zero, and both
        # paths cost more per active shape: time them with every shape active.
        weights = realistic_weights(self.character.n_shapes, n_active=self.character.n_shapes)
        times: dict[str, list[float]] = {p.name: [] for p in candidates}
        for i in range(warmup + frames):
            for candidate in candidates:
                self._deformation = candidate
                t0 = time.perf_counter()
                self.draw(weights)
                self.finish()
                if i >= warmup:
                    times[candidate.name].append(time.perf_counter() - t0)
        medians = {path: float(np.median(t)) * 1e3 for path, t in times.items()}
        best = min(medians, key=medians.get)
        other = "cpu" if best == "gpu" else "gpu"
        report = (
            f"deformation path: {best} ({best} {medians[best]:.1f} ms, {other} {medians[other]:.1f} ms "
            f"median per frame over {frames} frames at {self.width}x{self.height})"
        )
        return next(p for p in candidates if p.name == best), report

    def set_msaa(self, msaa: int) -> bool:
        """Draw from now on with ``msaa`` samples (0: none) into new offscreen framebuffers; False (nothing
        changed) when drawing into a target framebuffer (a window's samples are the window's). Whoever holds
        :attr:`fbo` (an overlay drawing into it) must take the new one."""
        if not self._framebuffers.owned:
            return False
        samples = min(int(msaa), int(self.ctx.max_samples)) if int(msaa) > 1 else 0
        if samples != self.samples:
            self._framebuffers.release()
            self._framebuffers = Framebuffers(self.ctx, (self.width, self.height), samples, None)
            self.fbo, self.samples = self._framebuffers.fbo, samples
        return True

    def median_draw_ms(self, frames: int = 8, warmup: int = 2) -> float:
        """Median ms of drawing a frame with every shape active and waiting for it (the live budget check)."""
        weights = realistic_weights(self.character.n_shapes, n_active=self.character.n_shapes)
        times = []
        for i in range(warmup + frames):
            t0 = time.perf_counter()
            self.draw(weights)
            self.finish()
            if i >= warmup:
                times.append(time.perf_counter() - t0)
        return float(np.median(times)) * 1e3

    # -- per frame: the CPU side -------------------------------------------
    def prepare(self, weights: np.ndarray, head_rotation: np.ndarray | None = None,
                head_translation: np.ndarray | None = None) -> None:
        """The CPU side of a frame: pose, then the path's active weights or CPU deformation, and uploads."""
        w = check_weights(weights, self.character.n_shapes)
        joints = None
        if self.parts and self._head_pose.available:  # the head turns through the skeleton, the body stays
            self._pose = model_matrix(None, head_translation)
            if self._motion is not None:
                joints = self._motion.matrices(head_rotation, self._pose)
            else:
                joints = self._head_pose.matrices(head_rotation) if head_rotation is not None else None
        else:
            self._pose = model_matrix(head_rotation, head_translation, self.character.pivot)
        self._deformation.prepare(w, joints)

    def advance(self, t: float, frame: Frame | None = None) -> None:
        """The next frame's time (seconds, the loop's tick time) and its frame (eye-look channels): what the
        spring bones step to and the eyes look by. Without it each drawn frame advances 1/60 s."""
        if self._motion is not None:
            self._motion.set_frame(t, frame)

    @property
    def spring_ms(self) -> float | None:
        """The last frame's spring simulation time, ms; None when nothing is simulated."""
        return self._motion.spring_ms if self._motion is not None and self._motion.springs is not None else None

    def prepare_controls(self, controls: np.ndarray, head_rotation: np.ndarray | None = None,
                         head_translation: np.ndarray | None = None) -> None:
        """The CPU side of an elastic frame from control displacements, (n_controls, 3) float32."""
        if not isinstance(self._deformation, ElasticPath):
            raise ValueError("prepare_controls: only the 'elastic' path takes control displacements "
                             f"(path is {self.path!r})")
        self._pose = model_matrix(head_rotation, head_translation, self.character.pivot)
        self._deformation.prepare_controls(controls)

    # -- per frame: the draw passes ----------------------------------------
    def submit(self, clock: PassClock | NoClock = NO_CLOCK) -> None:
        """Issue the draw calls for the prepared frame, pass by pass (never waits for the GPU, unless a
        :class:`~facepuppet.runtime.render.pass_clock.PassClock` in "finish" mode times the passes)."""
        self._set_frame_uniforms()
        self._deformation.bind()
        clock.mark("setup")
        self._clear()
        clock.mark("clear")
        if self.parts:
            self._draw_opaque_groups()
            clock.mark("opaque")
            self._draw_blended_groups()
            clock.mark("blended")
        else:
            self._draw_surfaces()
            clock.mark("opaque")
            self._draw_layers()
            clock.mark("blended")
        if self._label is not None:
            self._label.draw()
            clock.mark("label")

    def resolve(self, clock: PassClock | NoClock = NO_CLOCK) -> None:
        """The MSAA resolve of the frame (what reading it back starts with); nothing when not multisampled."""
        if self.samples:
            self._framebuffers.resolved()
            clock.mark("resolve")

    def _set_frame_uniforms(self) -> None:
        """The pose and the camera, in every program of the path."""
        model, view_projection = self._pose.T.tobytes(), self.camera.view_projection.T.tobytes()
        eye = tuple(float(x) for x in self.camera.eye)
        for prog in self._deformation.programs.values():
            prog["u_model"].write(model)
            prog["u_view_projection"].write(view_projection)
            if "u_eye" in prog:  # an unlit or toon variant does not read it
                prog["u_eye"].value = eye

    def _clear(self) -> None:
        """Bind the framebuffer and clear it; depth test on, the blend function every blended pass uses."""
        self.fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.fbo.clear(*((0.0, 0.0, 0.0, 0.0) if self.transparent else (*self.background, 1.0)), depth=1.0)
        # Straight colour over, alpha accumulated as coverage: alpha stays right over a transparent clear.
        self.ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,
                               moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)

    def _draw_surfaces(self) -> None:
        """A character without parts, its one-sided kinds: back faces culled (unless ``cull_back_faces`` is
        off)."""
        n = self._n_surface_indices
        if n:
            self.ctx.front_face = "ccw"
            if self.cull_back_faces:
                self.ctx.enable(moderngl.CULL_FACE)
            self._deformation.vaos[None].render(moderngl.TRIANGLES, vertices=n)
        self.ctx.disable(moderngl.CULL_FACE)

    def _draw_layers(self) -> None:
        """A character without parts, its thin two-sided layers (eye occlusion, films, lashes): blended over the
        finished surfaces, without writing depth so that each shows through the ones drawn after it."""
        first = self._first_layer_index
        if self.n_indices > first:
            self.ctx.enable(moderngl.BLEND)
            self.fbo.depth_mask = False
            self._deformation.vaos[None].render(moderngl.TRIANGLES, vertices=self.n_indices - first, first=first)
            self.fbo.depth_mask = True
            self.ctx.disable(moderngl.BLEND)

    def _draw_opaque_groups(self) -> None:
        """A character with parts, its opaque draw groups (culled ones first, then double-sided)."""
        self.ctx.front_face = "ccw"
        self._draw_groups([g for g in self._groups if not g.blend])

    def _draw_blended_groups(self) -> None:
        """A character with parts, its blended draw groups: far to near, depth writes off."""
        blended = [g for g in self._groups if g.blend]
        if len(blended) > 1:  # per frame: a handful of group centres
            eye = self.camera.eye - self._pose[:3, 3]
            blended.sort(key=lambda g: -float(np.dot(g.centre - eye, g.centre - eye)))
        self._draw_groups(blended)
        self.ctx.disable(moderngl.BLEND)
        self.fbo.depth_mask = True

    def _draw_groups(self, groups: list) -> None:
        """One draw call per group with its material and texture; culling as each group asks (off after)."""
        ctx, look, variants, vaos = self.ctx, self._look, self._variant_of, self._deformation.vaos
        culling = None
        for g in groups:
            if g.cull != culling:
                (ctx.enable if g.cull else ctx.disable)(moderngl.CULL_FACE)
                culling = g.cull
            if g.blend:
                ctx.enable(moderngl.BLEND)
                self.fbo.depth_mask = False
            self._materials[g.material].bind_to_uniform_block(0)
            t = int(look.texture[g.material])
            if t >= 0:
                self._textures[t].use(BASE_TEXTURE_UNIT)
            vaos[variants[g.material]].render(moderngl.TRIANGLES, vertices=g.count, first=g.first)
        ctx.disable(moderngl.CULL_FACE)

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

    # -- reading back --------------------------------------------------------
    def read_pixels(self) -> np.ndarray:
        """The last frame as ndarray of shape (height, width, 3), uint8, top row first; (height, width, 4)
        RGBA with straight (not premultiplied) colour when the background is transparent."""
        fbo = self._framebuffers.resolved()  # the MSAA resolve, when multisampled
        k = 4 if self.transparent else 3
        data = fbo.read(viewport=(0, 0, self.width, self.height), components=k, alignment=1)
        image = np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width, k)[::-1].copy()
        if self.transparent:  # the framebuffer holds colour x alpha over the clear (0, 0, 0, 0)
            straighten(image)
        return image

    def read_rgba(self) -> np.ndarray:
        """The last frame as the framebuffer holds it: (height, width, 4) uint8 RGBA, bottom row first, colour x
        alpha when transparent (read-only); the cheapest read, finished elsewhere by
        :func:`~facepuppet.runtime.render.readback.finish_rgba`."""
        fbo = self._framebuffers.resolved()
        data = fbo.read(viewport=(0, 0, self.width, self.height), components=4, alignment=1)
        return np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width, 4)

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
        self._deformation.release()
        for obj in self._textures + self._materials:
            obj.release()
        if self._label is not None:
            self._label.release()
        self._attr_vbo.release()
        self._ibo.release()
        self._framebuffers.release()
