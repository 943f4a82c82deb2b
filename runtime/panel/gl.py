"""Dear ImGui's draw data drawn through our own moderngl context (``shaders/panel.glsl``).

What a renderer of ImGui 1.92 has to do (Dear ImGui's own documentation of
``ImDrawData`` and ``ImTextureData``; moderngl-window's integration takes a
plain moderngl context the same way):

* **Textures.** The renderer declares ``ImGuiBackendFlags_RendererHasTextures``;
  ImGui then lists, in ``ImDrawData.Textures``, every texture it wants made
  (``WantCreate``: upload the RGBA pixels, hand back an id with ``SetTexID``,
  set the status ``OK``), refreshed (``WantUpdates``: the font atlas grew new
  glyphs) or released (``WantDestroy``). Here an id is an index into our own
  table of moderngl textures, never a raw GL name.
* **Geometry.** Each draw list holds ``ImDrawVert`` (2 float position in
  pixels, 2 float texture coordinate, 4 byte colour: 20 bytes) and 32-bit
  indices (imgui-bundle's ``ImDrawIdx``; Dear ImGui's default is 16); each
  command draws ``ElemCount`` indices from ``IdxOffset`` (no ``RendererHasVtxOffset``:
  ImGui keeps ``VtxOffset`` 0), one texture, and one clip rectangle that becomes
  the scissor box (GL's y runs up, ImGui's down).
* **State.** Alpha blending (colour over, alpha accumulated), no depth test, no
  culling, scissor on; restored for the character's renderer afterwards.

The buffers are read straight from ImGui's memory (``data_address``) into one
vertex and one index buffer per draw list, grown by doubling and reused:
nothing is allocated per frame once the panel's size has settled.
"""

from __future__ import annotations

import ctypes
from typing import Any

import moderngl
import numpy as np

from facepuppet.runtime.render.shader_loader import load_program

VERTEX_BYTES = 20  # sizeof(ImDrawVert): ImVec2 pos, ImVec2 uv, ImU32 col
INDEX_BYTES = 4  # sizeof(ImDrawIdx): imgui-bundle builds Dear ImGui with 32-bit indices (ImDrawIdx unsigned int)


class ImguiGL:
    """Draws ImGui's draw data into a moderngl framebuffer.

    Parameters
    ----------
    ctx : moderngl.Context, the run's own context (window or headless EGL)
    imgui : the ``imgui_bundle.imgui`` module (its context already created)
    """

    def __init__(self, ctx: moderngl.Context, imgui: Any) -> None:
        self.ctx = ctx
        self.imgui = imgui
        io = imgui.get_io()
        # RendererHasVtxOffset is not declared: ImGui then leaves VtxOffset 0 (moderngl's render has no
        # base vertex), which 32-bit indices never need
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures.value
        self.prog = load_program(ctx, "panel.glsl")
        self.prog["u_texture"].value = 0
        self._textures: dict[int, moderngl.Texture] = {}
        self._next_id = 1  # 0 means "no texture" to ImGui
        self._slots: list[tuple[moderngl.Buffer, moderngl.Buffer, moderngl.VertexArray]] = []
        status = imgui.ImTextureStatus
        self._status = (status.want_create, status.want_updates, status.want_destroy, status.ok, status.destroyed)

    # -- textures -----------------------------------------------------------------------------------

    def _sync_textures(self, draw_data) -> None:
        want_create, want_updates, want_destroy, ok, destroyed = self._status
        for tex in draw_data.textures:
            st = tex.status
            if st == want_create or st == want_updates:
                if tex.format != self.imgui.ImTextureFormat.rgba32:
                    raise RuntimeError(f"panel: ImGui asked for texture format {tex.format}, only RGBA32 is handled")
                pixels = np.asarray(tex.get_pixels_array(), dtype=np.uint8)
                tid = int(tex.tex_id) if st == want_updates else 0
                gl_tex = self._textures.get(tid)
                if gl_tex is None or gl_tex.size != (tex.width, tex.height):
                    if gl_tex is not None:
                        gl_tex.release()
                    gl_tex = self.ctx.texture((tex.width, tex.height), 4, pixels.tobytes())
                    gl_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                    gl_tex.repeat_x = gl_tex.repeat_y = False
                    if tid == 0:
                        tid, self._next_id = self._next_id, self._next_id + 1
                    self._textures[tid] = gl_tex
                else:  # the whole atlas again: a few hundred KiB, only when glyphs were added
                    gl_tex.write(pixels.tobytes())
                tex.set_tex_id(tid)
                tex.set_status(ok)
            elif st == want_destroy and tex.unused_frames > 0:
                gl_tex = self._textures.pop(int(tex.tex_id), None)
                if gl_tex is not None:
                    gl_tex.release()
                tex.set_tex_id(0)
                tex.set_status(destroyed)

    # -- geometry -----------------------------------------------------------------------------------

    def _slot(self, i: int, vtx_bytes: int, idx_bytes: int):
        while len(self._slots) <= i:
            vbo = self.ctx.buffer(reserve=64 * 1024, dynamic=True)
            ibo = self.ctx.buffer(reserve=32 * 1024, dynamic=True)
            self._slots.append((vbo, ibo, self._vao(vbo, ibo)))
        vbo, ibo, vao = self._slots[i]
        if vbo.size < vtx_bytes or ibo.size < idx_bytes:
            vao.release()
            if vbo.size < vtx_bytes:
                vbo.orphan(max(vtx_bytes, 2 * vbo.size))
            if ibo.size < idx_bytes:
                ibo.orphan(max(idx_bytes, 2 * ibo.size))
            vao = self._vao(vbo, ibo)
            self._slots[i] = (vbo, ibo, vao)
        return vbo, ibo, vao

    def _vao(self, vbo: moderngl.Buffer, ibo: moderngl.Buffer) -> moderngl.VertexArray:
        return self.ctx.vertex_array(self.prog, [(vbo, "2f 2f 4f1", "in_position", "in_uv", "in_color")],
                                     index_buffer=ibo, index_element_size=INDEX_BYTES)

    def render(self, draw_data: Any, fbo: moderngl.Framebuffer) -> int:
        """Draw ``draw_data`` (``imgui.get_draw_data()`` after ``imgui.render()``) into ``fbo``.

        Returns the number of draw commands issued.
        """
        self._sync_textures(draw_data)
        dpx, dpy = draw_data.display_pos.x, draw_data.display_pos.y
        dw, dh = draw_data.display_size.x, draw_data.display_size.y
        sx, sy = draw_data.framebuffer_scale.x, draw_data.framebuffer_scale.y
        fb_w, fb_h = int(dw * sx), int(dh * sy)
        if fb_w <= 0 or fb_h <= 0 or draw_data.cmd_lists_count == 0:
            return 0
        ctx = self.ctx
        fbo.use()
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        self.prog["u_display_pos"].value = (dpx, dpy)
        self.prog["u_display_size"].value = (dw, dh)
        n_cmds = 0
        try:
            for i in range(draw_data.cmd_lists_count):
                dl = draw_data.cmd_lists[i]
                nv, ni = dl.vtx_buffer.size(), dl.idx_buffer.size()
                if nv == 0 or ni == 0:
                    continue
                vtx_bytes, idx_bytes = nv * VERTEX_BYTES, ni * INDEX_BYTES
                vbo, ibo, vao = self._slot(i, vtx_bytes, idx_bytes)
                vbo.write(ctypes.string_at(dl.vtx_buffer.data_address(), vtx_bytes))
                ibo.write(ctypes.string_at(dl.idx_buffer.data_address(), idx_bytes))
                for j in range(dl.cmd_buffer.size()):
                    cmd = dl.cmd_buffer[j]
                    if cmd.user_callback_data is not None and cmd.elem_count == 0:
                        continue
                    c = cmd.clip_rect
                    x1, y1 = max((c.x - dpx) * sx, 0.0), max((c.y - dpy) * sy, 0.0)
                    x2, y2 = min((c.z - dpx) * sx, fb_w), min((c.w - dpy) * sy, fb_h)
                    if x2 <= x1 or y2 <= y1:
                        continue
                    fbo.scissor = (int(x1), int(fb_h - y2), int(x2 - x1 + 0.5), int(y2 - y1 + 0.5))
                    tex = self._textures.get(int(cmd.get_tex_id()))
                    if tex is None:
                        continue
                    tex.use(0)
                    vao.render(moderngl.TRIANGLES, vertices=cmd.elem_count, first=cmd.idx_offset)
                    n_cmds += 1
        finally:
            fbo.scissor = None
            ctx.disable(moderngl.BLEND)
            ctx.enable(moderngl.DEPTH_TEST)
        return n_cmds

    def release(self) -> None:
        for vbo, ibo, vao in self._slots:
            vao.release()
            vbo.release()
            ibo.release()
        self._slots = []
        for tex in self._textures.values():
            tex.release()
        self._textures = {}
