"""Pictures of a trained actor: the K actuations at s = 1, and the actuation signals of a take (Pillow)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageDraw

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.images import contact_sheet, point_box, save_png

LABEL_WEIGHT = 0.1  # a weight from this up is listed on its cell of the face actuation sheet

if TYPE_CHECKING:
    import moderngl

_BG, _NEUTRAL, _MOVED, _LINK = (250, 250, 248), (150, 150, 150), (200, 40, 30), (60, 90, 200)


def _view(points: np.ndarray, lo: np.ndarray, span: float, size: int) -> np.ndarray:
    """Front view (x to the image's right as seen from the front, so the subject's left on the right), pixels."""
    margin = 0.08 * size
    scale = (size - 2 * margin) / span
    return np.c_[margin + (points[:, 0] - lo[0]) * scale, size - margin - (points[:, 1] - lo[1]) * scale]


def actuation_images(actor: Actor, size: int = 220, strength: float = 1.0) -> list[tuple[str, np.ndarray]]:
    """One front-view figure per actuation: neutral markers (grey) and x(s = strength e_k) (red)."""
    neutral = actor.neutral.astype(np.float64)
    poses = [actor.evaluate(np.eye(actor.n_actuations)[k] * strength) for k in range(actor.n_actuations)]
    every = np.vstack([neutral, *poses])
    lo, hi = every.min(axis=0), every.max(axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-9))
    lo = (lo + hi) / 2 - span / 2
    base = _view(neutral, lo, span, size)
    out = []
    for k, pose in enumerate(poses):
        img = Image.new("RGB", (size, size), _BG)
        draw = ImageDraw.Draw(img)
        moved = _view(pose, lo, span, size)
        for (x0, y0), (x1, y1) in zip(base, moved):
            draw.line([(x0, y0), (x1, y1)], fill=_LINK, width=2)
            draw.ellipse([x0 - 2, y0 - 2, x0 + 2, y0 + 2], fill=_NEUTRAL)
            draw.ellipse([x1 - 3, y1 - 3, x1 + 3, y1 + 3], fill=_MOVED)
        largest = float(np.max(np.linalg.norm(pose - neutral, axis=1)))
        out.append((f"s{k + 1:02d}=1  max {largest:.2f} {actor.units}", np.asarray(img)))
    return out


def actuation_sheet(actor: Actor, path: str | os.PathLike, columns: int = 5) -> Path:
    """Contact sheet of the K actuations at s = 1 as marker figures; returns the PNG path."""
    return save_png(path, contact_sheet(actuation_images(actor), columns))


def signal_plot(s: np.ndarray, rate: float, path: str | os.PathLike, width: int = 1200, lane: int = 48) -> Path:
    """Each actuation's signal over the take as one lane (0 and 1 marked), drawn with Pillow lines.

    s : ndarray of shape (n_frames, K), float; rate : frames per second
    """
    s = np.asarray(s, dtype=np.float64)
    n, k = s.shape
    left, top = 40, 10
    img = Image.new("RGB", (width, top + k * lane + 24), _BG)
    draw = ImageDraw.Draw(img)
    x = left + np.arange(n) * (width - left - 10) / max(n - 1, 1)
    lo, hi = min(-0.2, float(s.min())), max(1.2, float(s.max()))
    for j in range(k):
        y0 = top + j * lane
        to_y = lambda v, y0=y0: y0 + lane - 4 - (v - lo) / (hi - lo) * (lane - 8)  # noqa: E731
        for level, colour in ((0.0, (180, 180, 180)), (1.0, (220, 200, 200))):
            draw.line([(left, to_y(level)), (width - 10, to_y(level))], fill=colour)
        draw.text((4, y0 + lane / 2 - 6), f"s{j + 1:02d}", fill=(30, 30, 30))
        draw.line(list(zip(x.tolist(), to_y(s[:, j]).tolist())), fill=_LINK, width=1)
    seconds = n / rate
    for tick in np.arange(0, seconds + 1e-9, 5.0 if seconds > 20 else 1.0):
        xt = left + tick * rate * (width - left - 10) / max(n - 1, 1)
        draw.text((xt, top + k * lane + 6), f"{tick:.0f}s", fill=(30, 30, 30))
    path = Path(path)
    img.save(path, format="PNG")
    return path


def face_actuation_images(pair: ActorPair, character: Character, ctx: moderngl.Context,
                          size: tuple[int, int] = (320, 320), strength: float = 1.0,
                          path: str = "auto") -> list[tuple[str, np.ndarray]]:
    """Each actuation at s = ``strength`` e_k, transferred to ``character`` through ``pair`` and rendered.

    Parameters
    ----------
    pair : ActorPair, for ``character``
    character : Character
    ctx : moderngl.Context (a standalone EGL context will do)
    size : (width, height), pixels of each cell

    Returns [(label, ndarray of shape (height, width, 3), uint8)], the neutral first; each label names
    the actuation and how many weights reach ``LABEL_WEIGHT``, and the cell lists them all, largest first,
    with their values (as many as fit, then how many more and the largest of those left out): what a
    cell shows is the sum of them all, so naming two would call an open mouth "mouthFrown".
    """
    from facepuppet.runtime.render.renderer import FaceRenderer  # GL: the renderer imports moderngl

    k = pair.cubic.shape[1]
    zoom = 2                                      # render larger, then crop to the marked region of the face
    renderer = FaceRenderer(ctx, character, size[0] * zoom, size[1] * zoom, path=path, framing="face",
                            log=lambda line: None)
    box = point_box(renderer.project(character.vertices[pair.marker_vertices]), renderer.width,
                      renderer.height, size[0] / size[1])
    try:
        out = []
        for j in range(-1, k):
            s = np.zeros(k) if j < 0 else np.eye(k)[j] * strength
            w = pair.weights(s)
            renderer.draw(w)
            renderer.finish()
            shown = [i for i in np.argsort(-w, kind="stable") if w[i] >= LABEL_WEIGHT]
            cell = Image.fromarray(renderer.read_pixels()).crop(box).resize(size, Image.LANCZOS)
            _list_weights(cell, [(character.shape_names[i], float(w[i])) for i in shown])
            count = f"{len(shown)} weight{'s' if len(shown) != 1 else ''} >= {LABEL_WEIGHT:g}"
            out.append((f"neutral: {count}" if j < 0 else f"s{j + 1:02d}={strength:g}: {count}", np.asarray(cell)))
    finally:
        renderer.close()
    return out


def _list_weights(cell: Image.Image, weights: list[tuple[str, float]], line: int = 11) -> None:
    """Write ``(name, weight)`` lines in the cell's top-left corner on a dark band, as many as fit."""
    draw = ImageDraw.Draw(cell)
    room = max(1, (cell.height - 4) // line)
    lines = [f"{name} {value:.2f}" for name, value in weights]
    if len(lines) > room:
        rest = weights[room - 1:]
        lines = lines[:room - 1] + [f"+{len(rest)} more, each <= {rest[0][1]:.2f}"]
    for n, text in enumerate(lines):
        left, top, right, bottom = draw.textbbox((3, 2 + n * line), text)
        draw.rectangle((left - 2, top - 1, right + 2, bottom + 1), fill=(20, 20, 24))
        draw.text((3, 2 + n * line), text, fill=(235, 235, 235))


def face_actuation_sheet(pair: ActorPair, character: Character, path: str | os.PathLike, columns: int = 5,
                         ctx: moderngl.Context | None = None) -> Path:
    """Contact sheet of the neutral and the K actuations at s = 1 on the character's face; returns the PNG path."""
    own = ctx is None
    if own:
        import moderngl

        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    try:
        return save_png(path, contact_sheet(face_actuation_images(pair, character, ctx), columns))
    finally:
        if own:
            ctx.release()
