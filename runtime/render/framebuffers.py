"""The framebuffer a renderer draws into: a window's, or its own offscreen one, multisampled or not.

A multisampled framebuffer cannot be read directly: it is resolved (``copy_framebuffer``) into a plain
twin of the same size first.
"""

from __future__ import annotations

import moderngl


class Framebuffers:
    """Colour and depth to draw into, and where to read the picture from.

    Parameters
    ----------
    ctx : moderngl.Context
    size : tuple of 2 int, (width, height) pixels
    samples : int, 0 for none; the offscreen framebuffer's samples
    target_fbo : moderngl.Framebuffer or None; None makes an own offscreen framebuffer

    Attributes
    ----------
    fbo : moderngl.Framebuffer, drawn into
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], samples: int,
                 target_fbo: moderngl.Framebuffer | None) -> None:
        self.ctx = ctx
        self._own = target_fbo is None
        # Bound again on release, so that no deleted framebuffer stays bound.
        self._previous = ctx.fbo or ctx.detect_framebuffer(0)
        self._resolve = None
        if target_fbo is None:
            self._color = ctx.renderbuffer(size, 4, samples=samples)
            self._depth = ctx.depth_renderbuffer(size, samples=samples)
            self.fbo = ctx.framebuffer(self._color, self._depth)
            if samples:  # multisampled: resolved into a plain one before reading
                self._resolve_color = ctx.renderbuffer(size, 4)
                self._resolve = ctx.framebuffer(self._resolve_color)
        else:
            self.fbo = target_fbo

    @property
    def owned(self) -> bool:
        """Whether the framebuffers are this object's own (offscreen), not a target's."""
        return self._own

    def resolved(self) -> moderngl.Framebuffer:
        """The framebuffer to read: the multisampled one resolved into its plain twin, or the one drawn into."""
        if self._resolve is None:
            return self.fbo
        self.ctx.copy_framebuffer(self._resolve, self.fbo)
        return self._resolve

    def release(self) -> None:
        """Release the own framebuffers (a target framebuffer is its owner's) and bind the one bound before."""
        if not self._own:
            return
        self._previous.use()
        self.fbo.release()
        self._color.release()
        self._depth.release()
        if self._resolve is not None:
            self._resolve.release()
            self._resolve_color.release()
