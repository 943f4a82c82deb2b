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

The draw lists are copied straight from ImGui's memory (``data_address``) into
one staging array of vertices and one of indices (a list's indices moved by the
vertices of the lists before it), uploaded as one vertex and one index buffer
per frame, grown by doubling and reused: nothing is allocated per frame once
the panel's size has settled. Uniforms are written only when the display
changes, the texture bound only when it changes between commands.
"""

from __future__ import annotations

import ctypes
import time
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
        self._vbo: moderngl.Buffer | None = None
        self._ibo: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self._vtx = self._idx = None  # staging arrays the draw lists are copied into
        self._addresses = (0, 0)  # their data addresses
        self._display: tuple | None = None
        self._cmds: list = []  # the last frame's draw commands (redraw)
        self.draw_calls_s = 0.0  # seconds in the last frame's draw calls (llvmpipe: its vertex work runs in them)
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

    def _buffers(self, vtx_bytes: int, n_idx: int) -> tuple[moderngl.Buffer, moderngl.Buffer, moderngl.VertexArray]:
        """The one vertex and index buffer (and their staging arrays) for a frame of this size, grown by doubling."""
        if self._vao is None or self._vbo.size < vtx_bytes or self._ibo.size < n_idx * INDEX_BYTES:
            if self._vao is not None:
                self._vao.release()
                self._vbo.release()
                self._ibo.release()
            vbo_size = max(vtx_bytes, 2 * (self._vbo.size if self._vbo is not None else 64 * 1024))
            ibo_size = max(n_idx * INDEX_BYTES, 2 * (self._ibo.size if self._ibo is not None else 32 * 1024))
            self._vbo = self.ctx.buffer(reserve=vbo_size, dynamic=True)
            self._ibo = self.ctx.buffer(reserve=ibo_size, dynamic=True)
            self._vao = self.ctx.vertex_array(self.prog, [(self._vbo, "2f 2f 4f1", "in_position", "in_uv", "in_color")],
                                              index_buffer=self._ibo, index_element_size=INDEX_BYTES)
            self._vtx = np.empty(vbo_size, dtype=np.uint8)
            self._idx = np.empty(ibo_size // INDEX_BYTES, dtype=np.uint32)
            self._addresses = (self._vtx.ctypes.data, self._idx.ctypes.data)  # read once: .ctypes is not free
        return self._vbo, self._ibo, self._vao

    def render(self, draw_data: Any, fbo: moderngl.Framebuffer) -> int:
        """Draw ``draw_data`` (``imgui.get_draw_data()`` after ``imgui.render()``) into ``fbo``.

        Every draw list goes into one vertex and one index buffer (one upload each per frame; a list's indices
        moved by the vertices before it), then one draw call per command (its clip rectangle as the scissor box).
        Returns the number of draw commands issued.
        """
        self._sync_textures(draw_data)
        dpx, dpy = draw_data.display_pos.x, draw_data.display_pos.y
        dw, dh = draw_data.display_size.x, draw_data.display_size.y
        sx, sy = draw_data.framebuffer_scale.x, draw_data.framebuffer_scale.y
        fb_w, fb_h = int(dw * sx), int(dh * sy)
        n_lists = draw_data.cmd_lists_count
        if fb_w <= 0 or fb_h <= 0 or n_lists == 0:
            self._cmds = []
            return 0
        lists = []
        nv_all = ni_all = 0
        for i in range(n_lists):
            dl = draw_data.cmd_lists[i]
            nv, ni = dl.vtx_buffer.size(), dl.idx_buffer.size()
            if nv and ni:
                lists.append((dl, nv, ni, nv_all, ni_all))
                nv_all += nv
                ni_all += ni
        if not lists:
            self._cmds = []
            return 0
        vbo, ibo, vao = self._buffers(nv_all * VERTEX_BYTES, ni_all)
        vtx, idx = self._vtx, self._idx
        vtx_at, idx_at = self._addresses
        for dl, nv, ni, v0, i0 in lists:  # straight from ImGui's memory into the staging arrays
            ctypes.memmove(vtx_at + v0 * VERTEX_BYTES, dl.vtx_buffer.data_address(), nv * VERTEX_BYTES)
            ctypes.memmove(idx_at + i0 * INDEX_BYTES, dl.idx_buffer.data_address(), ni * INDEX_BYTES)
            if v0:
                idx[i0:i0 + ni] += v0
        vbo.write(vtx[:nv_all * VERTEX_BYTES])
        ibo.write(idx[:ni_all])
        display = (dpx, dpy, dw, dh)
        if display != self._display:  # uniforms only when the display moved or changed size
            self.prog["u_display_pos"].value = (dpx, dpy)
            self.prog["u_display_size"].value = (dw, dh)
            self._display = display
        cmds = []  # (texture, scissor box, index count, first index): what redraw() issues again
        for dl, _, _, _, i0 in lists:
            buf = dl.cmd_buffer
            for j in range(buf.size()):
                cmd = buf[j]
                n = cmd.elem_count
                if n == 0:
                    continue
                c = cmd.clip_rect
                x1, y1 = max((c.x - dpx) * sx, 0.0), max((c.y - dpy) * sy, 0.0)
                x2, y2 = min((c.z - dpx) * sx, fb_w), min((c.w - dpy) * sy, fb_h)
                if x2 <= x1 or y2 <= y1:
                    continue
                tex = self._textures.get(int(cmd.get_tex_id()))
                if tex is None:
                    continue
                cmds.append((tex, (int(x1), int(fb_h - y2), int(x2 - x1 + 0.5), int(y2 - y1 + 0.5)), n,
                             i0 + cmd.idx_offset))
        self._cmds = cmds
        return self.redraw(fbo)

    def redraw(self, fbo: moderngl.Framebuffer) -> int:
        """Issue the last frame's draw calls again (its buffers are still uploaded): the panel between two
        ImGui frames. Returns the number of draw commands issued."""
        cmds, vao = self._cmds, self._vao
        if not cmds or vao is None:
            self.draw_calls_s = 0.0
            return 0
        ctx = self.ctx
        if ctx.fbo is not fbo:  # drawn after the character: its framebuffer (and viewport) are bound already
            fbo.use()
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        bound = None
        calls_s = 0.0
        clock = time.perf_counter
        try:
            for tex, box, n, first in cmds:
                if tex is not bound:
                    tex.use(0)
                    bound = tex
                fbo.scissor = box
                t = clock()
                vao.render(moderngl.TRIANGLES, vertices=n, first=first)
                calls_s += clock() - t
        finally:
            self.draw_calls_s = calls_s
            fbo.scissor = None
            ctx.disable(moderngl.BLEND)
            ctx.enable(moderngl.DEPTH_TEST)
        return len(cmds)

    def release(self) -> None:
        if self._vao is not None:
            self._vao.release()
            self._vbo.release()
            self._ibo.release()
        self._vbo = self._ibo = self._vao = None
        self._cmds = []
        for tex in self._textures.values():
            tex.release()
        self._textures = {}
