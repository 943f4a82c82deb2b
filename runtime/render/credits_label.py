"""The credits line a licence asks for, drawn over every frame in the bottom-left corner.

The text is rendered once with Pillow (:func:`~facepuppet.runtime.render.images.label_image`) into an
RGBA texture; each frame draws it on a pixel-exact quad, blended, without depth.
"""

from __future__ import annotations

import moderngl
import numpy as np

from facepuppet.runtime.render.images import label_image
from facepuppet.runtime.render.shader_loader import load_program

MARGIN = 8  # pixels from the left and bottom edges


class CreditsLabel:
    """One line of text over a ``width`` x ``height`` framebuffer (twice the size from 600 pixels high).

    Parameters
    ----------
    ctx : moderngl.Context
    text : str, non-empty
    width, height : int, pixels of the framebuffer drawn into
    """

    def __init__(self, ctx: moderngl.Context, text: str, width: int, height: int) -> None:
        self.ctx = ctx
        image = label_image(text, scale=2 if height >= 600 else 1)
        h, w = image.shape[:2]
        self.size = (w, h)
        self.texture = ctx.texture((w, h), 4, np.ascontiguousarray(image[::-1]).tobytes())  # GL rows bottom first
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        x0, y0 = -1 + 2 * MARGIN / width, -1 + 2 * MARGIN / height
        x1, y1 = x0 + 2 * w / width, y0 + 2 * h / height
        quad = np.array([[x0, y0, 0, 0], [x1, y0, 1, 0], [x1, y1, 1, 1], [x0, y1, 0, 1]], np.float32)
        self.prog = load_program(ctx, "text_overlay.glsl")
        self.vbo = ctx.buffer(quad.tobytes())
        self.ibo = ctx.buffer(np.array([0, 1, 2, 0, 2, 3], np.uint32).tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f 2f", "in_position", "in_uv")], index_buffer=self.ibo,
                                    index_element_size=4)

    def draw(self) -> None:
        """Blend the label over the frame (depth test off for the draw, on again after)."""
        ctx = self.ctx
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        self.texture.use(0)
        self.prog["u_label"].value = 0
        self.vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)

    def release(self) -> None:
        for obj in (self.prog, self.vbo, self.ibo, self.vao, self.texture):
            obj.release()
