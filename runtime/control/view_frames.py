"""The drawn frames of a run, with alpha, for the view page (an OBS Browser Source): read back and framed.

The frame loop's thread only reads the picture back from the GPU (:func:`grab`: the renderer's ``read_rgba``,
as GL stores it: rows bottom-up, colour premultiplied by alpha over the transparent clear), and only
while a view page is connected and its next frame is due; compressing and sending happen on the control
server's thread. The page inflates the bytes (the browser's ``DecompressionStream``), turns the rows over
and divides the colour by alpha (canvas ``ImageData`` is straight alpha).

A view message is binary: the header :data:`HEADER` (28 bytes, little-endian, unpadded: ``b"FPV1"``, width u32,
height u32, flags u32, tick index u32, capture time f64 in ms since the epoch, for the page's lag) then the zlib
stream of
``width * height * 4`` bytes.
"""

from __future__ import annotations

import struct
import time
import zlib
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import Renderer

HEADER = struct.Struct("<4sIIIId")
MAGIC = b"FPV1"
BOTTOM_UP = 1  # rows as GL reads them, the last row first
PREMULTIPLIED = 2  # colour times alpha (the framebuffer's over a transparent clear)
MAX_VIEW_PIXELS = 1280 * 720  # larger pictures are sent at half size each way


def grab(renderer: Renderer) -> tuple[int, int, int, np.ndarray]:
    """(width, height, flags, RGBA pixels, C-contiguous) of the renderer's last drawn frame, as cheaply as it
    can be read.

    A renderer with ``read_rgba`` (:class:`~facepuppet.runtime.render.renderer.FaceRenderer`, the elastic path)
    is read as the framebuffer holds it (premultiplied, bottom-up: no conversion on the frame loop's thread);
    another renderer's ``read_pixels`` is taken (top row first, straight alpha, opaque when it has none).
    Pictures over MAX_VIEW_PIXELS are halved each way by taking every other pixel."""
    read = getattr(renderer, "read_rgba", None)
    if read is not None:
        image = read()
        flags = BOTTOM_UP | (PREMULTIPLIED if getattr(renderer, "transparent", False) else 0)
    else:
        image = np.asarray(renderer.read_pixels())
        flags = 0
        if image.shape[2] == 3:
            image = np.concatenate([image, np.full(image.shape[:2] + (1,), 255, np.uint8)], axis=2)
    if image.shape[0] * image.shape[1] > MAX_VIEW_PIXELS:
        image = image[::2, ::2]
    return image.shape[1], image.shape[0], flags, np.ascontiguousarray(image)


def encode(width: int, height: int, flags: int, k: int, t_capture_ms: float, rgba: bytes | np.ndarray,
           level: int = 1) -> bytes:
    """One view message (see the module docstring); zlib at ``level`` (1: fast; a transparent background
    compresses to almost nothing)."""
    return HEADER.pack(MAGIC, width, height, flags, k & 0xFFFFFFFF, t_capture_ms) + zlib.compress(rgba, level)


def decode(message: bytes) -> tuple[int, int, int, int, float, np.ndarray]:
    """(width, height, flags, k, t_capture_ms, (height, width, 4) uint8 as sent); ValueError for a bad one."""
    if len(message) < HEADER.size:
        raise ValueError("view message: shorter than its header")
    magic, w, h, flags, k, t_ms = HEADER.unpack_from(message)
    if magic != MAGIC or w * h * 4 > 4 * 3840 * 2160:
        raise ValueError("view message: not a view frame")
    raw = zlib.decompressobj().decompress(message[HEADER.size:], w * h * 4)
    if len(raw) != w * h * 4:
        raise ValueError("view message: its pixels are not width x height x 4 bytes")
    return w, h, flags, k, t_ms, np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 4)


def now_ms() -> float:
    """Milliseconds since the epoch (the page's ``Date.now()`` clock: its lag is its time less this)."""
    return time.time() * 1e3
