"""Write frames as PNG and lay labelled frames out on a contact sheet (Pillow)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

LABEL_HEIGHT = 18  # pixels under each cell for its label
_SHEET_BACKGROUND = (24, 25, 28)
_LABEL_COLOR = (225, 225, 225)


def check_rgb(image: np.ndarray, name: str = "image") -> np.ndarray:
    """An image as (h, w, 3) uint8, or ValueError saying what came."""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name}: expected an (h, w, 3) uint8 RGB array, got {a.shape} {a.dtype}")
    return a


def save_png(path: str | os.PathLike, rgb: np.ndarray) -> Path:
    """Write ``rgb`` (ndarray of shape (h, w, 3), uint8, top row first) as a PNG; returns the path."""
    from facepuppet.runtime.outputs import atomic_path

    path = Path(path)
    image = Image.fromarray(check_rgb(rgb, str(path)))
    with atomic_path(path) as temp:       # never a half-written PNG under the final name
        image.save(temp, format="PNG")
    return path


def contact_sheet(images: list[tuple[str, np.ndarray]], columns: int) -> np.ndarray:
    """A grid of equally sized images, each with its label underneath.

    Parameters
    ----------
    images : list of (label, ndarray of shape (h, w, 3), uint8); all the same size
    columns : int, >= 1

    Returns
    -------
    sheet : ndarray of shape (rows * (h + LABEL_HEIGHT), columns * w, 3), uint8,
        rows = ceil(len(images) / columns)
    """
    if not images:
        raise ValueError("contact_sheet: expected at least one (label, image) pair, got none")
    if columns < 1:
        raise ValueError(f"contact_sheet: columns must be >= 1, got {columns}")
    h, w, _ = check_rgb(images[0][1], images[0][0]).shape
    rows = -(-len(images) // columns)
    cell_h = h + LABEL_HEIGHT
    sheet = Image.new("RGB", (columns * w, rows * cell_h), _SHEET_BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for i, (label, rgb) in enumerate(images):
        rgb = check_rgb(rgb, label)
        if rgb.shape[:2] != (h, w):
            raise ValueError(f"contact_sheet: image {label!r} is {rgb.shape[1]}x{rgb.shape[0]}, expected {w}x{h}")
        x, y = (i % columns) * w, (i // columns) * cell_h
        sheet.paste(Image.fromarray(rgb), (x, y))
        text = str(label)
        left, _, right, _ = draw.textbbox((0, 0), text, font=font)
        draw.text((x + max(2, (w - (right - left)) // 2), y + h + 3), text, fill=_LABEL_COLOR, font=font)
    return np.asarray(sheet)
