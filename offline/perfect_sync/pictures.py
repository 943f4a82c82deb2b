"""A contact sheet of a perfect-sync character's cloned shapes, each at weight 1, rendered on its face (GL)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from facepuppet.runtime.character import Character
from facepuppet.runtime.render.images import contact_sheet, save_png

if TYPE_CHECKING:
    import moderngl


def shape_images(character: Character, names: Sequence[str], ctx: moderngl.Context,
                 size: tuple[int, int] = (240, 240)) -> list[tuple[str, np.ndarray]]:
    """[(label, (h, w, 3) uint8)]: the neutral, then each named shape at weight 1, all cropped to the square
    around every pixel any of them changes (grown by a third), so that small features fill the cells."""
    from facepuppet.runtime.render.renderer import FaceRenderer

    zoom = 4
    renderer = FaceRenderer(ctx, character, size[0] * zoom, size[1] * zoom, framing="face", log=lambda line: None)
    try:
        frames = []
        for name in (None, *names):
            w = np.zeros(character.n_shapes, np.float32)
            if name is not None:
                w[character.shape_names.index(name)] = 1.0
            renderer.draw(w)
            renderer.finish()
            frames.append(("neutral" if name is None else name, renderer.read_pixels()))
    finally:
        renderer.close()
    base = frames[0][1].astype(np.int16)
    changed = np.zeros(base.shape[:2], bool)
    for _, f in frames[1:]:
        changed |= np.abs(f.astype(np.int16) - base).max(axis=2) > 12
    h, w = changed.shape
    if changed.any():
        ys, xs = np.nonzero(changed)
        centre = np.array([(xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2])
        half = max(xs.max() - xs.min(), ys.max() - ys.min()) / 2 * 1.33 + 8
    else:
        centre, half = np.array([w / 2, h / 2]), min(w, h) / 2
    half = min(half, w / 2, h / 2)
    cx, cy = float(np.clip(centre[0], half, w - half)), float(np.clip(centre[1], half, h - half))
    box = tuple(int(round(v)) for v in (cx - half, cy - half, cx + half, cy + half))
    return [(label, np.asarray(Image.fromarray(f).crop(box).resize(size, Image.LANCZOS))) for label, f in frames]


def shape_sheet(character: Character, names: Sequence[str], path: str | os.PathLike, columns: int = 8,
                ctx: moderngl.Context | None = None) -> Path:
    """Contact sheet PNG of the neutral and the named shapes; returns its path (a standalone EGL context when
    ``ctx`` is None; GLUnavailable when there is none)."""
    own = ctx is None
    if own:
        import moderngl

        from facepuppet.runtime.render.gl_context import GLUnavailable

        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as exc:
            raise GLUnavailable(f"no headless EGL OpenGL 3.3 context for the contact sheet ({exc})") from None
    try:
        return save_png(path, contact_sheet(shape_images(character, names, ctx), columns))
    finally:
        if own:
            ctx.release()
