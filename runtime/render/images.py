"""Write frames as PNG and lay labelled frames out on a contact sheet (Pillow)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import atomic_path

LABEL_HEIGHT = 18  # pixels under each cell for its label
_SHEET_BACKGROUND = (24, 25, 28)
_LABEL_COLOR = (225, 225, 225)


def check_rgb(image: np.ndarray, name: str = "image", alpha: bool = False) -> np.ndarray:
    """An image as (h, w, 3) uint8 (or (h, w, 4) RGBA with ``alpha``), or ValueError saying what came."""
    a = np.asarray(image)
    channels = (3, 4) if alpha else (3,)
    if a.ndim != 3 or a.shape[2] not in channels or a.dtype != np.uint8 or a.shape[0] == 0 or a.shape[1] == 0:
        what = "RGB or RGBA" if alpha else "RGB"
        raise ValueError(f"{name}: expected an (h, w, {'|'.join(map(str, channels))}) uint8 {what} array, "
                         f"got {a.shape} {a.dtype}")
    return a


def point_box(pixels: np.ndarray, width: int, height: int, aspect: float,
              margin: float = 0.25) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) pixels: the points' bounding box grown by ``margin`` and widened (or made
    taller) to ``aspect`` (width / height), kept inside the ``width`` x ``height`` image.

    A contact sheet's cells cropped to it show the part of the picture that matters (a face, its markers)
    at the cell's size instead of a small head in a wide frame.
    """
    pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    lo, hi = pixels.min(axis=0), pixels.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * (1 + margin)
    half = np.maximum(half, [half[1] * aspect, half[0] / aspect])
    half = np.minimum(half, [width / 2, height / 2])
    centre = np.clip(centre, half, [width - half[0], height - half[1]])
    return tuple(int(round(v)) for v in (*(centre - half), *(centre + half)))


def save_png(path: str | os.PathLike, rgb: np.ndarray) -> Path:
    """Write ``rgb`` (ndarray of shape (h, w, 3) RGB or (h, w, 4) RGBA, uint8, top row first) as a PNG;
    returns the path."""
    path = Path(path)
    image = Image.fromarray(check_rgb(rgb, str(path), alpha=True))
    with atomic_path(path) as temp:       # never a half-written PNG under the final name
        image.save(temp, format="PNG")
    return path


def contact_sheet(images: list[tuple[str, np.ndarray]], columns: int) -> np.ndarray:
    """A grid of equally sized images, each with its label underneath.

    Parameters
    ----------
    images : list of (label, ndarray of shape (h, w, 3) or RGBA (h, w, 4), uint8); all the same size;
        RGBA cells are composited over the sheet's background
    columns : int, >= 1

    Returns
    -------
    sheet : ndarray of shape (rows * (h + LABEL_HEIGHT), columns * w, 3), uint8,
        rows = ceil(len(images) / columns)
    """
    if not images:
        raise ValueError("contact_sheet: expected at least one (label, image) pair, got none")
    if columns < 1:
        raise UsageError(f"contact_sheet: columns must be >= 1, got {columns}")
    h, w, _ = check_rgb(images[0][1], images[0][0], alpha=True).shape
    rows = -(-len(images) // columns)
    cell_h = h + LABEL_HEIGHT
    sheet = Image.new("RGB", (columns * w, rows * cell_h), _SHEET_BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for i, (label, rgb) in enumerate(images):
        rgb = check_rgb(rgb, label, alpha=True)
        if rgb.shape[:2] != (h, w):
            raise ValueError(f"contact_sheet: image {label!r} is {rgb.shape[1]}x{rgb.shape[0]}, expected {w}x{h}")
        x, y = (i % columns) * w, (i // columns) * cell_h
        cell = Image.fromarray(rgb)
        sheet.paste(cell, (x, y), cell if rgb.shape[2] == 4 else None)
        text = str(label)
        left, _, right, _ = draw.textbbox((0, 0), text, font=font)
        draw.text((x + max(2, (w - (right - left)) // 2), y + h + 3), text, fill=_LABEL_COLOR, font=font)
    return np.asarray(sheet)


def label_image(text: str, scale: int = 1, pad: int = 4) -> np.ndarray:
    """``text`` as a straight-alpha RGBA label (light text on a half-dark box), (h, w, 4) uint8, top row first."""
    font = ImageFont.load_default()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    left, top, right, bottom = probe.textbbox((0, 0), text, font=font)
    w, h = right - left + 2 * pad, bottom - top + 2 * pad
    image = Image.new("RGBA", (w, h), (0, 0, 0, 150))
    ImageDraw.Draw(image).text((pad - left, pad - top), text, fill=(*_LABEL_COLOR, 255), font=font)
    if scale > 1:
        image = image.resize((w * scale, h * scale), Image.NEAREST)
    return np.asarray(image)


def with_footer(sheet: np.ndarray, text: str) -> np.ndarray:
    """``sheet`` (h, w, 3) uint8 with a row below it holding ``text`` (the attribution), left-aligned."""
    label = label_image(text)
    h, w = label.shape[:2]
    footer = np.empty((h + 4, sheet.shape[1], 3), np.uint8)
    footer[:] = sheet[-1, -1]
    w = min(w, sheet.shape[1] - 4)
    a = label[:, :w, 3:4].astype(np.float32) / 255.0
    footer[2:2 + h, 4:4 + w] = (label[:, :w, :3] * a + footer[2:2 + h, 4:4 + w] * (1 - a)).astype(np.uint8)
    return np.vstack([sheet, footer])
