"""The blendshape deltas as ``shaders/blendshapes.glsl`` takes them: 16-bit steps, one texture, the active list.

Each delta component is stored as a 16-bit offset from zero in steps of its shape (the shape's largest
component over ``DELTA_STEPS``); the gpu path reads them from one texture, and the cpu path draws the same
rounded deltas (:func:`on_delta_grid`), so that both paths draw one surface.
"""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np

from facepuppet.runtime.model.character import Character

DELTA_TEXTURE_WIDTH = 4096
#: Steps of a delta component either side of zero (16-bit offsets; blendshapes.glsl)
DELTA_STEPS = 32767


def delta_steps(character: Character) -> np.ndarray:
    """Per shape, the size of one step of its position and of its normal deltas (n_shapes, 2), float64.

    A step is the shape's largest |component| of that kind over ``DELTA_STEPS`` (0 for a shape
    that moves nothing of the kind), so each delta component is within half a step of its 16-bit
    value: at most 1/65534 of the shape's largest.
    """
    c = character
    steps = np.zeros((c.n_shapes, 2))
    for s in range(c.n_shapes):
        sl = c.shape_slice(s)
        for k, src in enumerate((c.delta_positions, c.delta_normals)):
            if sl.stop > sl.start:
                steps[s, k] = float(np.abs(src[sl]).max()) / DELTA_STEPS
    return steps


def delta_offsets(character: Character) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every stored delta component as its 16-bit offset from zero, in steps of its shape (:func:`delta_steps`).

    Returns
    -------
    positions, normals : ndarray of shape (len(delta_indices), 3), int32, in [-32767, 32767], row for row
        with ``delta_positions`` / ``delta_normals``
    steps : ndarray of shape (n_shapes, 2), float64
    """
    c = character
    steps = delta_steps(c)
    out = []
    for k, src in enumerate((c.delta_positions, c.delta_normals)):
        q = np.zeros(src.shape, np.int32)
        for s in range(c.n_shapes):
            sl = c.shape_slice(s)
            if steps[s, k] > 0:
                q[sl] = np.rint(src[sl] / steps[s, k])
        out.append(q)
    return out[0], out[1], steps


def on_delta_grid(character: Character) -> Character:
    """``character`` with every delta component on its shape's 16-bit grid (:func:`delta_offsets`), as the
    gpu path's texture holds them: the cpu path draws these, so both paths draw the same surface (with the
    file's deltas a vertex moved up to 1/65534 of its shape's largest delta apart, and where that moved an
    edge across a pixel's centre the two paths' pictures differed by that pixel)."""
    c = character
    q_pos, q_nrm, steps = delta_offsets(c)
    step_of_row = np.repeat(steps, np.diff(c.delta_offsets), axis=0)  # (len(delta_indices), 2)
    return dataclasses.replace(c, delta_positions=(q_pos * step_of_row[:, :1]).astype(np.float32),
                               delta_normals=(q_nrm * step_of_row[:, 1:]).astype(np.float32))


def delta_texture(ctx: moderngl.Context, character: Character) -> tuple[moderngl.Texture, np.ndarray]:
    """Position and normal deltas of every shape in one RGB32UI texture of width DELTA_TEXTURE_WIDTH.

    Texel ``shape * n_vertices + vertex`` holds that shape's six delta components (position x y z,
    normal x y z) as 16-bit offsets ``q + 32768`` (:func:`delta_offsets`), two per word, low half first;
    32768 (exactly zero) where the shape does not move the vertex. One fetch per active shape and
    vertex where two float textures took two: on llvmpipe the fetches are the whole cost of the
    vertex shader's sum (the ICT head, 10 shapes active: 6.4 ms of the vertex stage with two
    RGB32F fetches, the loop without fetches nothing), and the texture is half the size.

    Returns
    -------
    texture : moderngl.Texture, RGB32UI, nearest
    steps : ndarray of shape (n_shapes, 2), float32, :func:`delta_steps` (what a weight is multiplied by)
    """
    c = character
    n = c.n_vertices
    q_pos, q_nrm, steps = delta_offsets(c)
    rows = max(1, -(-(c.n_shapes * n) // DELTA_TEXTURE_WIDTH))
    texels = np.full((rows * DELTA_TEXTURE_WIDTH, 6), 32768, dtype=np.uint16)
    shape_of_row = np.repeat(np.arange(c.n_shapes), np.diff(c.delta_offsets))
    texel = shape_of_row * n + c.delta_indices.astype(np.int64)
    texels[texel] = np.hstack([q_pos, q_nrm]) + 32768
    # little-endian uint16 pairs read as uint32: the first of each pair is the low half
    tex = ctx.texture((DELTA_TEXTURE_WIDTH, rows), 3, texels.astype("<u2").tobytes(), dtype="u4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex, steps.astype(np.float32)


def active_uniforms(weights: np.ndarray, steps: np.ndarray, max_active: int) -> tuple[int, np.ndarray, np.ndarray]:
    """The active shapes of a frame as blendshapes.glsl takes them.

    At most ``max_active`` non-zero weights (the largest in magnitude when there are more).

    Returns
    -------
    count : int
    shapes : ndarray of shape (max_active,), int32, the first ``count`` used
    weights : ndarray of shape (max_active, 2), float32, weight times the shape's (position, normal) step
    """
    w = np.asarray(weights, np.float32)
    active = np.flatnonzero(w)
    if len(active) > max_active:
        keep = np.argsort(-np.abs(w[active]), kind="stable")[:max_active]
        active = np.sort(active[keep])
    count = len(active)
    shapes = np.zeros(max_active, np.int32)
    scaled = np.zeros((max_active, 2), np.float32)
    shapes[:count] = active
    scaled[:count] = w[active, None] * steps[active]
    return count, shapes, scaled
