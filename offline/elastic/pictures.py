"""Pictures of the elastic model: originals vs reconstructions, cloned expressions, control points and muscles."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageDraw

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.images import contact_sheet, save_png
from facepuppet.runtime.render.renderer import FaceRenderer

if TYPE_CHECKING:
    import moderngl

CELL = (240, 240)


def _renderers(ctx, character, model, cell):
    quiet = lambda s: None  # noqa: E731
    dense = FaceRenderer(ctx, character, *cell, path="cpu", log=quiet, framing="face") if character.n_shapes else None
    elastic = FaceRenderer(ctx, character, *cell, path="elastic", elastic=model, log=quiet, framing="face")
    if dense is not None:
        elastic.camera = dense.camera  # the same view for both
    return dense, elastic


def reconstruction_sheets(ctx: moderngl.Context, character: Character, model: ElasticModel,
                          out_dir: str | os.PathLike, per_sheet: int = 16,
                          cell: tuple[int, int] = CELL) -> list[Path]:
    """Original (dense deltas) beside reconstruction (elastic path) for every shape; returns the PNG paths."""
    dense, elastic = _renderers(ctx, character, model, cell)
    pairs = []
    for s, name in enumerate(character.shape_names):
        w = np.zeros(character.n_shapes, np.float32)
        w[s] = 1.0
        dense.draw(w)
        a = dense.read_pixels()
        elastic.draw(w)
        pairs += [(f"{name} original", a), (f"{name} elastic", elastic.read_pixels())]
    paths = []
    for i in range(0, len(pairs), 2 * per_sheet):
        path = Path(out_dir) / f"reconstruction_{i // (2 * per_sheet) + 1:02d}.png"
        paths.append(save_png(path, contact_sheet(pairs[i : i + 2 * per_sheet], columns=8)))
    dense.close()
    elastic.close()
    return paths


def expression_sheet(ctx: moderngl.Context, character: Character, model: ElasticModel, names: Sequence[str],
                     path: str | os.PathLike, cell: tuple[int, int] = CELL) -> Path:
    """The named expressions (and muscles) of ``model`` drawn on ``character`` with the elastic path."""
    _, elastic = _renderers(ctx, character, model, cell)
    images = [("neutral", _draw(elastic, model, None))]
    for name in names:
        values = np.zeros(len(model.channel_names), np.float32)
        values[model.channel_names.index(name)] = 1.0
        images.append((name, _draw(elastic, model, values)))
    sheet = save_png(path, contact_sheet(images, columns=min(6, len(images))))
    elastic.close()
    return sheet


def _draw(renderer, model, values):
    controls = np.zeros((model.n_controls, 3), np.float32) if values is None else model.controls(values)
    renderer.prepare_controls(controls)
    renderer.submit()
    return renderer.read_pixels()


def overlay(ctx: moderngl.Context, character: Character, model: ElasticModel, path: str | os.PathLike,
            size: tuple[int, int] = (640, 640)) -> Path:
    """Neutral face with the control points (dots, names) and muscles (lines, ellipses) drawn over it."""
    r = FaceRenderer(ctx, character, *size, path="elastic", elastic=model, log=lambda s: None, framing="face")
    image = Image.fromarray(_draw(r, model, None))
    pen = ImageDraw.Draw(image)
    a = model.arrays
    for (x, y), name in zip(r.project(a["control_positions"]), model.control_names):
        pen.ellipse([x - 3, y - 3, x + 3, y + 3], fill=(255, 230, 40))
        pen.text((x + 4, y - 5), name.replace("_", " "), fill=(255, 255, 200))
    for kind, pts, ranges in zip(a["muscle_kinds"], a["muscle_points"], a["muscle_ranges"]):
        if kind == 0:  # linear: attachment → insertion
            (x0, y0), (x1, y1) = r.project(pts)
            pen.line([x0, y0, x1, y1], fill=(230, 60, 60), width=3)
            pen.ellipse([x0 - 4, y0 - 4, x0 + 4, y0 + 4], outline=(230, 60, 60), width=2)
        else:  # sphincter: ellipse of semi-axes lx, ly around the centre
            c = pts[0]
            box = r.project([c - [ranges[0], ranges[1], 0], c + [ranges[0], ranges[1], 0]])
            (x0, y1), (x1, y0) = box
            pen.ellipse([min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1)], outline=(80, 160, 255), width=3)
    r.close()
    image.save(path)
    return Path(path)
