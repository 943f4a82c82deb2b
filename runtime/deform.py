"""CPU blendshape deformation with NumPy: the renderer's alternative to the vertex shader.

    x = x0 + sum_s w_s d_s          (positions)
    n = normalise(n0 + sum_s w_s e_s)   (normals; e_s = normal delta of shape s)

Only the active (non-zero) shapes are touched: per active shape one
in-place BLAS ``saxpy`` over a contiguous row of the dense delta matrix.
Positions and normals are interleaved per vertex, ``[x y z nx ny nz]``, which
is the vertex-buffer layout of the renderer's CPU path, so a frame is one
copy, a few saxpys and one buffer write.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import saxpy

from .character import Character
from .geometry import vertex_normals


def check_weights(weights, n_shapes: int) -> np.ndarray:
    """Weights as (n_shapes,) float32, or ValueError saying what came."""
    w = np.asarray(weights, dtype=np.float32)
    if w.shape != (n_shapes,):
        raise ValueError(f"weights: expected shape ({n_shapes},) in character shape order, got {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError("weights: contain NaN or infinity")
    return w


class CpuDeformer:
    """Deform a character's vertices and normals on the CPU.

    Parameters
    ----------
    character : Character

    Attributes
    ----------
    rest : ndarray of shape (n_vertices, 6), float32, neutral [position, normal]
    deltas : ndarray of shape (n_shapes, n_vertices * 6), float32, interleaved position/normal deltas
    """

    def __init__(self, character: Character):
        self.character = character
        n = character.n_vertices
        rest = np.empty((n, 6), dtype=np.float32)
        rest[:, :3] = character.vertices
        rest[:, 3:] = vertex_normals(character.vertices, character.triangles)
        self.rest = rest
        deltas = np.zeros((character.n_shapes, n, 6), dtype=np.float32)
        for s in range(character.n_shapes):
            sl = character.shape_slice(s)
            idx = character.delta_indices[sl]
            deltas[s, idx, :3] = character.delta_positions[sl]
            deltas[s, idx, 3:] = character.delta_normals[sl]
        self.deltas = deltas.reshape(character.n_shapes, n * 6)
        self._out = np.empty((n, 6), dtype=np.float32)

    def deform_into(self, weights: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Interleaved deformed [position, normal] with normals NOT renormalised.

        The hot path of the renderer: the vertex shader renormalises, exactly
        as on the GPU path. ``weights`` must already be (n_shapes,) float32.

        Returns
        -------
        out : ndarray of shape (n_vertices, 6), float32 (an internal buffer unless ``out`` is given)
        """
        out = self._out if out is None else out
        np.copyto(out, self.rest)
        flat = out.reshape(-1)
        for s in np.flatnonzero(weights):
            saxpy(self.deltas[s], flat, a=float(weights[s]))
        return out

    def deform(self, weights) -> tuple[np.ndarray, np.ndarray]:
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
