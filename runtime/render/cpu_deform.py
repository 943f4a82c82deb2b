"""CPU blendshape deformation with NumPy: the renderer's alternative to the vertex shader.

    x = x0 + sum_s w_s d_s          (positions)
    n = normalise(n0 + sum_s w_s e_s)   (normals; e_s = normal delta of shape s)

Only vertices some shape moves are touched, gathered into a few contiguous
spans; a frame is one matrix-vector product over their deltas when many
shapes are active, or one in-place BLAS ``saxpy`` per active shape when few are.
Positions and normals are interleaved per vertex, ``[x y z nx ny nz]``, which
is the vertex-buffer layout of the renderer's CPU path, so the result goes
to the vertex buffer as it is.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import saxpy

from facepuppet.runtime.model.character import Character


def check_weights(weights: np.ndarray, n_shapes: int) -> np.ndarray:
    """Weights as (n_shapes,) float32, or ValueError saying what came."""
    w = np.asarray(weights, dtype=np.float32)
    if w.shape != (n_shapes,):
        raise ValueError(f"weights: expected shape ({n_shapes},) in character shape order, got {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError("weights: contain NaN or infinity")
    return w


def moving_spans(moving: np.ndarray, max_gap: int = 64) -> np.ndarray:
    """Contiguous [first, end) vertex ranges covering ``moving``, merged across gaps of <= ``max_gap``.

    Parameters
    ----------
    moving : ndarray of shape (m,), int, sorted unique vertex indices that some shape moves
    max_gap : int >= 0

    Returns
    -------
    spans : ndarray of shape (n_spans, 2), int64
    """
    moving = np.asarray(moving, dtype=np.int64)
    if moving.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    breaks = np.flatnonzero(np.diff(moving) > max_gap + 1)
    starts = np.concatenate([moving[:1], moving[breaks + 1]])
    ends = np.concatenate([moving[breaks] + 1, moving[-1:] + 1])
    return np.stack([starts, ends], axis=1)


class CpuDeformer:
    """Deform a character's vertices and normals on the CPU.

    Only vertices that some shape moves take part: they are gathered into a
    few contiguous spans of the vertex order (short runs of still vertices
    between them are kept, so that there are few spans), and the deltas are
    stored for those spans only. A frame with many active shapes is one
    matrix-vector product over that block (it streams each delta once); a
    frame with few is one ``saxpy`` per active shape.

    Parameters
    ----------
    character : Character
    max_gap : int, runs of at most this many still vertices are kept inside a span

    Attributes
    ----------
    rest : ndarray of shape (n_vertices, 6), float32, neutral [position, normal]
    spans : ndarray of shape (n_spans, 2), int64, [first, end) vertex ranges that shapes move
    deltas : ndarray of shape (n_shapes, n_span_vertices * 6), float32, interleaved position/normal
        deltas of the span vertices, spans concatenated in order
    """

    def __init__(self, character: Character, max_gap: int = 64) -> None:
        self.character = character
        n = character.n_vertices
        rest = np.empty((n, 6), dtype=np.float32)
        rest[:, :3] = character.vertices
        rest[:, 3:] = character.rest_normals()
        self.rest = rest
        self.spans = moving_spans(np.unique(character.delta_indices), max_gap)
        lengths = self.spans[:, 1] - self.spans[:, 0]
        starts = np.concatenate([[0], np.cumsum(lengths)])           # span offsets in the block
        local = np.full(n, -1, dtype=np.int64)                        # vertex -> row of the block
        for (a, b), o in zip(self.spans, starts[:-1]):
            local[a:b] = np.arange(o, o + b - a)
        deltas = np.zeros((character.n_shapes, int(starts[-1]), 6), dtype=np.float32)
        for s in range(character.n_shapes):
            sl = character.shape_slice(s)
            rows = local[character.delta_indices[sl]]
            deltas[s, rows, :3] = character.delta_positions[sl]
            deltas[s, rows, 3:] = character.delta_normals[sl]
        self.deltas = deltas.reshape(character.n_shapes, 6 * int(starts[-1]))  # (0, 0) for a character without shapes
        self._block_rest = np.concatenate([rest[a:b].reshape(-1) for a, b in self.spans]) if len(self.spans) \
            else np.zeros(0, np.float32)
        self._block = np.empty_like(self._block_rest)
        self._pieces = [(a, b, 6 * int(o), 6 * int(o + b - a)) for (a, b), o in zip(self.spans, starts[:-1])]
        self._out = rest.copy()

    def deform_into(self, weights: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Interleaved deformed [position, normal] with normals NOT renormalised.

        The hot path of the renderer: the vertex shader renormalises, exactly
        as on the GPU path. ``weights`` must already be (n_shapes,) float32.

        Returns
        -------
        out : ndarray of shape (n_vertices, 6), float32 (an internal buffer unless ``out`` is given;
            the internal buffer's still vertices are written once, at construction)
        """
        if out is None:
            out = self._out
        else:
            np.copyto(out, self.rest)
        block = self._block
        if not len(block):  # no shape moves a vertex (shapes that only carry an expression's material binds)
            return out
        active = np.flatnonzero(weights)
        # measured on the ICT head: a saxpy per shape costs ~1.4x a shape's share of the product
        if 3 * len(active) >= 2 * len(weights):
            np.matmul(weights, self.deltas, out=block)
            block += self._block_rest
        else:
            np.copyto(block, self._block_rest)
            for s in active:
                saxpy(self.deltas[s], block, a=float(weights[s]))
        flat = out.reshape(-1)
        for a, b, p, q in self._pieces:
            flat[6 * a:6 * b] = block[p:q]
        return out

    def deform(self, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Deformed positions and unit normals.

        Parameters
        ----------
        weights : array_like of shape (n_shapes,), float, in character shape order

        Returns
        -------
        positions : ndarray of shape (n_vertices, 3), float32, character units
        normals : ndarray of shape (n_vertices, 3), float32, unit length
        """
        w = check_weights(weights, self.character.n_shapes)
        out = self.deform_into(w, np.empty_like(self.rest))
        normals = out[:, 3:]
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        return out[:, :3].copy(), (normals / np.maximum(length, 1e-12)).astype(np.float32)
