"""The framebuffer's bytes as pictures: what the GPU holds (RGBA, bottom row first, colour x alpha over a
transparent clear) turned into what the outputs take (top row first; RGB, or RGBA with straight colour).

Reading RGBA as it is stored and nothing else is the cheapest read-back (no conversion in the driver, no
copy): a live output reads that in the frame loop and turns it top row first in its own thread
(:func:`top_first`, a copy row by row; :mod:`~facepuppet.runtime.live.frame_handoff`), keeping RGBA with
colour x alpha, which costs a tenth of dropping the alpha column (a copy with a stride) and composites over a
key colour without a division; :meth:`~facepuppet.runtime.render.renderer.FaceRenderer.read_pixels` gives the
finished picture at once (RGB, or straight RGBA), and :func:`finish_rgba` the same from the stored one.
"""

from __future__ import annotations

import numpy as np


def straighten(image: np.ndarray) -> np.ndarray:
    """Colour x alpha -> straight colour, in place, of an (h, w, 4) uint8 RGBA picture; returns it."""
    a = image[:, :, 3:4].astype(np.uint16)
    part = (a > 0) & (a < 255)
    straight = np.minimum((image[:, :, :3].astype(np.uint32) * 255 + a // 2) // np.maximum(a, 1), 255)
    image[:, :, :3] = np.where(part, straight, image[:, :, :3]).astype(np.uint8)
    return image


def top_first(raw: np.ndarray) -> np.ndarray:
    """The (h, w, 4) bottom-up RGBA of :meth:`FaceRenderer.read_rgba` top row first, colour x alpha kept;
    a new contiguous array."""
    return np.ascontiguousarray(raw[::-1])


def finish_rgba(raw: np.ndarray, transparent: bool) -> np.ndarray:
    """The (h, w, 4) bottom-up RGBA of :meth:`FaceRenderer.read_rgba` as ``read_pixels`` gives it: top row
    first, (h, w, 3) RGB, or (h, w, 4) RGBA with straight colour when ``transparent``; a new array."""
    if transparent:
        return straighten(raw[::-1].copy())
    return np.ascontiguousarray(raw[::-1, :, :3])
