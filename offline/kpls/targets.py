"""Target characters for the cyclic retarget evaluation, each with its expression correspondence.

Ouzounis, Kiliadis & Mousas train on *semantically matching expressions* of
two characters, each described by its own feature points. A target here is
the answer to: "at the source's expression w (source blendshape weights),
where are the target's feature points?", i.e. ``features(W)`` of shape
(n, 3 k_target), displacements from the target's neutral in target units.

==========================  ===============================================================
class                       correspondence (what the learnt map has to discover)
==========================  ===============================================================
:class:`LinearRigTarget`    the target's own blendshapes, matched by name:
                            y = F_B M w. Source features x = F_A w are linear in w too,
                            so the map x -> y is linear (the *control*)
:class:`WarpedSourceTarget` the blended source mesh, exaggerated by its own displacement
                            and warped into a cartoon face (:func:`stylise_warp`):
                            y = f(v + g(D w)) − f(v), non-linear in w
:class:`ExaggeratedRigTarget` the target's blendshapes matched by name, blended, then
                            exaggerated: y = g(F_B M w), non-linear in w
==========================  ===============================================================

The exaggeration g (:class:`Exaggeration`) grows each feature point's
displacement with its own size and with the whole expression's intensity:
g(d_i) = d_i (1 + a tanh(‖d_i‖ / s)) (1 + b tanh(E / s)), E the mean ‖d‖ over
the points. Big expressions get bigger, and one action (a jaw drop) changes
how far another (a smile) moves the face: what an animator's cartoon rig does
and a sum of weighted shapes cannot.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.geometry import vertex_normals

from facepuppet.offline.kpls.pairs import feature_matrix, feature_points, match_matrix

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@dataclass(frozen=True)
class Exaggeration:
    """g(d_i) = d_i (1 + gain tanh(‖d_i‖/scale)) (1 + coupling tanh(E/scale)); scale in character units."""

    gain: float = 1.0
    coupling: float = 0.5
    scale: float = 0.4

    def __call__(self, d: np.ndarray) -> np.ndarray:
        """Exaggerated displacements, same shape as ``d`` (n, k, 3)."""
        size = np.linalg.norm(d, axis=2, keepdims=True)
        intensity = size.mean(axis=1, keepdims=True)
        return d * (1.0 + self.gain * np.tanh(size / self.scale)) * \
            (1.0 + self.coupling * np.tanh(intensity / self.scale))


def _centre_of_kind(character: Character, kind: str, side: float = 0.0) -> np.ndarray | None:
    codes = character.material_params[:, 2].astype(int)
    tri = character.triangles[np.isin(character.triangle_material, np.flatnonzero(codes == MATERIAL_KINDS[kind]))]
    v = character.vertices[np.unique(tri)]
    if side:
        v = v[np.sign(v[:, 0]) == side]
    return v.mean(axis=0).astype(np.float64) if len(v) else None


def stylise_warp(character: Character, eye_scale: float = 1.35, jaw_stretch: float = 0.35,
                 taper: float = 0.12) -> Callable[[np.ndarray], np.ndarray]:
    """The cartoon warp f: (n, 3) -> (n, 3), units of ``character``.

    Enlarges each eye region by up to ``eye_scale`` with a Gaussian fall-off,
    lengthens everything below the mouth by a soft ramp of slope
    ``jaw_stretch`` and widens the cranium / narrows the chin by ``taper``.
    """
    lo, hi = character.vertices.min(0).astype(np.float64), character.vertices.max(0).astype(np.float64)
    size = float(np.linalg.norm(hi - lo))
    eyes = [_centre_of_kind(character, "eye", s) for s in (1.0, -1.0)]
    mouth = _centre_of_kind(character, "teeth")
    mouth_y = float(mouth[1]) if mouth is not None else float(lo[1] + 0.35 * (hi[1] - lo[1]))
    radius = 0.08 * size

    def warp(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        q = p.copy()
        for c in eyes:
            if c is not None:
                r2 = ((p - c) ** 2).sum(-1, keepdims=True)
                q += (p - c) * (eye_scale - 1.0) * np.exp(-r2 / radius ** 2)
        soft = 0.03 * size
        below = soft * np.logaddexp(0.0, (mouth_y - p[..., 1]) / soft)  # smooth max(0, mouth_y − y)
        q[..., 1] -= jaw_stretch * below
        q[..., 0] *= 1.0 + taper * np.tanh((p[..., 1] - mouth_y) / (0.15 * size))
        return q

    return warp


def warped_rig(character: Character, warp: Callable[[np.ndarray], np.ndarray], name: str) -> Character:
    """``character`` under ``warp``: neutral W(v), each shape W(v + d) − W(v) (zero where d is), normals
    recomputed; the rest of the character kept. The truth of a rig whose proportions a warp changed."""
    neutral = character.vertices.astype(np.float64)
    base = warp(neutral)
    tris = character.triangles.astype(np.int64)
    base_normals = vertex_normals(base, tris)
    dense = np.zeros((character.n_shapes, character.n_vertices, 3), np.float32)
    dense_n = np.zeros_like(dense)
    for s in range(character.n_shapes):
        sl = character.shape_slice(s)
        idx = character.delta_indices[sl].astype(np.int64)
        dense[s, idx] = (warp(neutral[idx] + character.delta_positions[sl]) - base[idx]).astype(np.float32)
        shaped = base.copy()
        shaped[idx] += dense[s, idx]
        dense_n[s] = vertex_normals(shaped, tris) - base_normals
    offsets, indices, positions = sparse_deltas(dense)
    normals = np.concatenate([dense_n[s, indices[offsets[s]:offsets[s + 1]]] for s in range(character.n_shapes)])
    return character.with_parts(name=name, vertices=base.astype(np.float32), delta_offsets=offsets,
                                delta_indices=indices, delta_positions=positions,
                                delta_normals=normals.astype(np.float32),
                                pivot=warp(character.pivot[None].astype(np.float64))[0].astype(np.float32))



def stylise(character: Character, eye_scale: float = 1.35, jaw_stretch: float = 0.35,
            taper: float = 0.12, name: str | None = None) -> Character:
    """A cartoon blendshape rig: the warp f applied to the neutral and to each shape, f(v + d_s) − f(v)."""
    w = warped_rig(character, stylise_warp(character, eye_scale, jaw_stretch, taper),
                   name or f"{character.name} (stylised)")
    return Character(
        name=w.name, units=character.units, vertices=w.vertices,
        triangles=character.triangles, triangle_material=character.triangle_material,
        vertex_color=character.vertex_color, material_names=character.material_names,
        material_params=character.material_params, pivot=w.pivot,
        shape_names=character.shape_names, delta_offsets=w.delta_offsets, delta_indices=w.delta_indices,
        delta_positions=w.delta_positions, delta_normals=w.delta_normals,
        metadata={"settings": {"stylised_from": character.name, "eye_scale": eye_scale,
                               "jaw_stretch": jaw_stretch, "taper": taper}},
    )


class _Target:
    """Shared parts: the target's geometry (``character``), its feature points and their neutral positions."""

    character: Character
    points: np.ndarray  # (k,) int64, target feature-point vertices
    matched: np.ndarray  # (n,) int64, source shapes with a counterpart expression
    linear: bool  # whether features() is linear in the source weights

    @property
    def neutral_points(self) -> np.ndarray:
        """(k, 3) float64, target units: the feature points on the target's neutral."""
        return self.character.vertices[self.points].astype(np.float64)

    def features(self, source_weights: np.ndarray) -> np.ndarray:
        """Target feature displacements (n, 3 k) float64 at the expressions of ``source_weights`` (n, n_source)."""
        W = np.asarray(source_weights, dtype=np.float64)
        if W.ndim != 2 or W.shape[1] != self.n_source:
            raise ValueError(f"{type(self).__name__}.features: source weights must have shape "
                             f"(n, {self.n_source}), got {W.shape}")
        return self._features(W)


class LinearRigTarget(_Target):
    """The target's own blendshapes by name: y = F_B M w (linear; the control).

    Parameters
    ----------
    source, target : Character
    k : int, target feature points (farthest points over its moving region), or ``points`` given
    pairing : list of (source, target) shape names, or None to match by name
    """

    linear = True

    def __init__(self, source: Character, target: Character, k: int = 37, points: ArrayLike | None = None,
                 pairing: Sequence[tuple[str, str]] | None = None, seed: int = 0) -> None:
        self.character, self.n_source = target, source.n_shapes
        self.points = feature_points(target, k, points, seed)
        M = match_matrix(source.shape_names, target.shape_names, pairing)
        self.matched = np.flatnonzero(M.any(axis=0))
        self._map = feature_matrix(target, self.points) @ M

    def _features(self, W):
        return W @ self._map.T


class ExaggeratedRigTarget(LinearRigTarget):
    """The target's blendshapes by name, blended, then exaggerated: y = g(F_B M w)."""

    linear = False

    def __init__(self, source: Character, target: Character, exaggeration: Exaggeration | None = None,
                 k: int = 37, points: ArrayLike | None = None, pairing: Sequence[tuple[str, str]] | None = None,
                 seed: int = 0) -> None:
        super().__init__(source, target, k, points, pairing, seed)
        self.exaggeration = exaggeration or Exaggeration(scale=_typical_move(self._map))

    def _features(self, W):
        d = super()._features(W).reshape(len(W), -1, 3)
        return self.exaggeration(d).reshape(len(W), -1)


class WarpedSourceTarget(_Target):
    """The blended source mesh, exaggerated and warped: y = f(v + g(D w)) − f(v).

    The target shares the source's topology; its neutral is f(v) (``character``
    is :func:`stylise` of the source, whose neutral that is).
    """

    linear = False

    def __init__(self, source: Character, exaggeration: Exaggeration | None = None, k: int = 37,
                 points: ArrayLike | None = None, seed: int = 0, **warp_settings: float) -> None:
        self.n_source = source.n_shapes
        self.matched = np.arange(source.n_shapes)
        self.character = stylise(source, name=f"{source.name} (stylised, exaggerated)", **warp_settings)
        self.points = feature_points(self.character, k, points, seed)
        self._warp = stylise_warp(source, **warp_settings)
        self._rest = source.vertices[self.points].astype(np.float64)
        self._blend = feature_matrix(source, self.points)
        self.exaggeration = exaggeration or Exaggeration(scale=_typical_move(self._blend))

    def _features(self, W):
        d = self.exaggeration((W @ self._blend.T).reshape(len(W), -1, 3))
        return (self._warp(self._rest[None] + d) - self._warp(self._rest)[None]).reshape(len(W), -1)


def _typical_move(F: np.ndarray) -> float:
    """Median over shapes of the largest feature-point move at weight 1, (3 k, n_shapes) -> units."""
    peak = np.linalg.norm(F.reshape(-1, 3, F.shape[1]), axis=1).max(axis=0)
    peak = peak[peak > 0]
    return float(np.median(peak)) if len(peak) else 1.0
