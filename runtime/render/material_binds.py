"""Expressions' material binds at run time: the material colours and texture offsets of a frame.

A VRM expression may change material colours (base, emission, shade, rim, outline) and the base
texture's scale and offset (:mod:`~facepuppet.runtime.model.material_model`). Its weight arrives as
the weight of a shape of its own, so a frame's shape weights say everything: each bound property is
``rest + Σ weight × (target − rest)`` over the binds that name it, as three-vrm applies them. Only the
materials some bind names are recomputed, and only when a bind shape's weight changed since the last
frame; the renderer uploads those materials' blocks again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.material_model import BIND_KINDS, MaterialModel, default_material_model

_TEXTURE = BIND_KINDS["textureTransform"]


@dataclass
class MaterialRows:
    """The per-material values that binds change, float64 (linear colours; the texture transform as
    :data:`~facepuppet.runtime.model.character_parts.UV_TRANSFORM_COLUMNS`)."""

    base_color: np.ndarray   # (n, 4)
    emissive: np.ndarray     # (n, 3)
    shade: np.ndarray        # (n, 3)
    rim: np.ndarray          # (n, 3)
    outline: np.ndarray      # (n, 3)
    uv_transform: np.ndarray  # (n, 5)

    @classmethod
    def of(cls, character: Character) -> MaterialRows:
        """The character's own values (every bind at weight 0)."""
        n = len(character.material_names)
        model = character.material_model or default_material_model(n)
        look = character.look
        if look is None:
            return cls(np.ones((n, 4)), np.zeros((n, 3)), np.zeros((n, 3)), model.mtoon[:, 7:10].astype(float),
                       model.mtoon[:, 2:5].astype(float), np.tile([0.0, 0, 0, 1, 1], (n, 1)))
        return cls(look.base_color.astype(float), look.emissive.astype(float), look.shading[:, 2:5].astype(float),
                   model.mtoon[:, 7:10].astype(float), model.mtoon[:, 2:5].astype(float),
                   look.uv_transform.astype(float))

    def copy(self) -> MaterialRows:
        return MaterialRows(*(a.copy() for a in (self.base_color, self.emissive, self.shade, self.rim,
                                                 self.outline, self.uv_transform)))


class MaterialBinds:
    """The material values of a frame from its shape weights.

    Parameters
    ----------
    character : Character (its ``material_model`` binds; none: nothing ever changes)

    Attributes
    ----------
    rows : MaterialRows, the values of the last :meth:`update`
    materials : ndarray of int, the materials some bind names
    """

    def __init__(self, character: Character) -> None:
        model: MaterialModel = character.material_model or default_material_model(len(character.material_names))
        self.rest = MaterialRows.of(character)
        self.rows = self.rest.copy()
        self.shape = model.bind_shape.astype(np.int64)
        self.material = model.bind_target[:, 0].astype(np.int64)
        self.kind = model.bind_target[:, 1].astype(np.int64)
        self.value = model.bind_value.astype(np.float64)
        self.materials = np.unique(self.material)
        self._last = None

    @property
    def active(self) -> bool:
        return bool(len(self.shape))

    def update(self, weights: np.ndarray) -> np.ndarray:
        """Recompute :attr:`rows` for the shape ``weights`` of a frame; the materials whose values changed
        (empty when no bind shape's weight changed)."""
        if not len(self.shape):
            return self.materials
        w = np.nan_to_num(np.asarray(weights, np.float64)[self.shape])
        if self._last is not None and np.array_equal(w, self._last):
            return self.materials[:0]
        self._last = w
        rest, rows = self.rest, self.rows
        for m in self.materials:  # back to rest, then every bind's share added
            rows.base_color[m], rows.emissive[m], rows.shade[m] = rest.base_color[m], rest.emissive[m], rest.shade[m]
            rows.rim[m], rows.outline[m], rows.uv_transform[m] = rest.rim[m], rest.outline[m], rest.uv_transform[m]
        for b in np.flatnonzero(w != 0):
            m, kind, target, wt = self.material[b], self.kind[b], self.value[b], w[b]
            if kind == BIND_KINDS["color"]:
                rows.base_color[m] += wt * (target - rest.base_color[m])
            elif kind == BIND_KINDS["emissionColor"]:
                rows.emissive[m] += wt * (target[:3] - rest.emissive[m])
            elif kind == BIND_KINDS["shadeColor"]:
                rows.shade[m] += wt * (target[:3] - rest.shade[m])
            elif kind == BIND_KINDS["rimColor"]:
                rows.rim[m] += wt * (target[:3] - rest.rim[m])
            elif kind == BIND_KINDS["outlineColor"]:
                rows.outline[m] += wt * (target[:3] - rest.outline[m])
            elif kind == _TEXTURE:  # scale u, v, offset u, v
                rows.uv_transform[m, 3:5] += wt * (target[:2] - rest.uv_transform[m, 3:5])
                rows.uv_transform[m, 0:2] += wt * (target[2:4] - rest.uv_transform[m, 0:2])
        return self.materials


__all__ = ["MaterialBinds", "MaterialRows"]
