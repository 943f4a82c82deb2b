"""A character: neutral mesh, materials and sparse blendshape deltas.

This is what the renderer draws and what ``import-rig`` writes. Deltas are
stored sparse per shape (only the vertices a shape moves), in CSR layout:

    shape s moves vertices delta_indices[delta_offsets[s]:delta_offsets[s+1]]
    by delta_positions[...] and turns their normals by delta_normals[...]

Normal deltas are (normal of the shape at weight 1) − (neutral normal); the
renderer blends them with the same weights as positions and renormalises,
which is exact at a single shape at weight 1 and close in between.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.tables import (
    Section,
    TableSchema,
    TablesError,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)

# Material kinds the shader knows (column 2 of ``material_params``).
MATERIAL_KINDS = {"skin": 0, "eye": 1, "teeth": 2, "mouth": 3, "lashes": 4, "hidden": 5, "lips": 6}

CHARACTER_SCHEMA = register_schema(
    TableSchema(
        kind="character",
        sections={
            "vertices": Section("float32", ("n_vertices", 3), "neutral vertex positions"),
            "triangles": Section("uint32", ("n_triangles", 3), "vertex indices, counter-clockwise"),
            "triangle_material": Section("uint16", ("n_triangles",), "material index per triangle"),
            "vertex_color": Section("float32", ("n_vertices", 3), "albedo per vertex, linear RGB 0..1"),
            "material_params": Section(
                "float32", ("n_materials", 4), "specular, shininess, material kind code, unused"
            ),
            "pivot": Section("float32", (3,), "centre of head rotation"),
            "delta_offsets": Section("int64", ("n_shapes+1",), "CSR row starts per shape"),
            "delta_indices": Section("uint32", ("n_deltas",), "moved vertex per delta"),
            "delta_positions": Section("float32", ("n_deltas", 3), "position delta"),
            "delta_normals": Section("float32", ("n_deltas", 3), "normal delta"),
        },
        channels=("shapes", "materials"),
        channel_dims={"shapes": "n_shapes", "materials": "n_materials"},
    )
)


def _fail(field_name: str, problem: str, path=None):
    raise TablesError(path, field_name, problem)


@dataclass(frozen=True, eq=False)
class Character:
    """A deformable character, validated when built.

    Attributes
    ----------
    name : str
    units : str, "cm", "mm" or "m"
    vertices : ndarray of shape (n_vertices, 3), float32, units
    triangles : ndarray of shape (n_triangles, 3), uint32
    triangle_material : ndarray of shape (n_triangles,), uint16
    vertex_color : ndarray of shape (n_vertices, 3), float32, linear RGB 0..1
    material_names : tuple of n_materials str
    material_params : ndarray of shape (n_materials, 4), float32: specular, shininess, kind code, 0
    pivot : ndarray of shape (3,), float32, units
    shape_names : tuple of n_shapes str
    delta_offsets : ndarray of shape (n_shapes + 1,), int64
    delta_indices : ndarray of shape (n_deltas,), uint32
    delta_positions : ndarray of shape (n_deltas, 3), float32, units
    delta_normals : ndarray of shape (n_deltas, 3), float32
    metadata : dict, settings/metrics/input hash carried into the manifest
    """

    name: str
    units: str
    vertices: np.ndarray
    triangles: np.ndarray
    triangle_material: np.ndarray
    vertex_color: np.ndarray
    material_names: tuple[str, ...]
    material_params: np.ndarray
    pivot: np.ndarray
    shape_names: tuple[str, ...]
    delta_offsets: np.ndarray
    delta_indices: np.ndarray
    delta_positions: np.ndarray
    delta_normals: np.ndarray
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n_v = len(self.vertices)
        if n_v == 0:
            _fail("vertices", "a character needs at least one vertex")
        if len(self.triangles) and int(self.triangles.max()) >= n_v:
            _fail("triangles", f"index {int(self.triangles.max())} out of range for {n_v} vertices")
        if len(self.triangle_material) and int(self.triangle_material.max()) >= len(self.material_names):
            _fail("triangle_material", f"material index out of range for {len(self.material_names)} materials")
        offsets = self.delta_offsets
        if len(offsets) != len(self.shape_names) + 1 or offsets[0] != 0 or np.any(np.diff(offsets) < 0):
            _fail("delta_offsets", "must start at 0, never decrease and have n_shapes + 1 entries")
        if offsets[-1] != len(self.delta_indices):
            _fail("delta_offsets", f"last offset {int(offsets[-1])} != n_deltas {len(self.delta_indices)}")
        if len(self.delta_indices) and int(self.delta_indices.max()) >= n_v:
            _fail("delta_indices", f"vertex index out of range for {n_v} vertices")
        validate(CHARACTER_SCHEMA, self._arrays(), self._channels())  # dtypes, shapes, finiteness
        for arr in self._arrays().values():
            arr.setflags(write=False)

    # -- sizes -------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_shapes(self) -> int:
        return len(self.shape_names)

    # -- tables ------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        return {
            "vertices": self.vertices,
            "triangles": self.triangles,
            "triangle_material": self.triangle_material,
            "vertex_color": self.vertex_color,
            "material_params": self.material_params,
            "pivot": self.pivot,
            "delta_offsets": self.delta_offsets,
            "delta_indices": self.delta_indices,
            "delta_positions": self.delta_positions,
            "delta_normals": self.delta_normals,
        }

    def _channels(self) -> dict[str, list[str]]:
        return {"shapes": list(self.shape_names), "materials": list(self.material_names)}

    def save(self, path: str | os.PathLike) -> Path:
        """Write the character as a tables file of kind ``character``."""
        settings = dict(self.metadata.get("settings", {}))
        settings.setdefault("name", self.name)
        return save_tables(path, "character", self._arrays(), units=self.units, channels=self._channels(),
                           settings=settings, metadata=self.metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Character:
        """Load and validate a ``character`` tables file (see :func:`load_tables`)."""
        t = load_tables(path, kind="character")
        a = t.arrays
        with naming_file(path):
            return cls(
                name=str(t.settings.get("name", Path(path).stem)),
                units=t.units,
                vertices=a["vertices"],
                triangles=a["triangles"],
                triangle_material=a["triangle_material"],
                vertex_color=a["vertex_color"],
                material_names=tuple(t.channels["materials"]),
                material_params=a["material_params"],
                pivot=a["pivot"],
                shape_names=tuple(t.channels["shapes"]),
                delta_offsets=a["delta_offsets"],
                delta_indices=a["delta_indices"],
                delta_positions=a["delta_positions"],
                delta_normals=a["delta_normals"],
                metadata=t.metadata,
            )

    # -- views -------------------------------------------------------------
    def shape_slice(self, s: int) -> slice:
        return slice(int(self.delta_offsets[s]), int(self.delta_offsets[s + 1]))

    def dense_deltas(self, normals: bool = False) -> np.ndarray:
        """Deltas as a dense ndarray of shape (n_shapes, n_vertices, 3), float32."""
        src = self.delta_normals if normals else self.delta_positions
        out = np.zeros((self.n_shapes, self.n_vertices, 3), dtype=np.float32)
        for s in range(self.n_shapes):
            sl = self.shape_slice(s)
            out[s, self.delta_indices[sl]] = src[sl]
        return out


def moving_vertices(character: Character, fraction: float = 0.05) -> np.ndarray:
    """Vertices some shape moves by more than ``fraction`` of the largest move, (k,) int64, sorted.

    The expressive part of the face (the renderer's ``"face"`` framing, the
    retargeting's feature-point region). A character whose shapes move no
    vertex at all (no shapes, no deltas, or only zero deltas) gives an empty
    array; each caller says what stands in for it.
    """
    lengths = np.linalg.norm(character.delta_positions, axis=1)
    if not len(lengths):
        return np.zeros(0, np.int64)
    return np.unique(character.delta_indices[lengths > fraction * lengths.max()]).astype(np.int64)


def sparse_deltas(
    dense: np.ndarray, tolerance: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR form of dense deltas, keeping vertices that move more than ``tolerance``.

    Parameters
    ----------
    dense : ndarray of shape (n_shapes, n_vertices, 3), float
    tolerance : float, units; a vertex whose delta length is <= tolerance is dropped

    Returns
    -------
    offsets : (n_shapes + 1,) int64
    indices : (n_deltas,) uint32
    values : (n_deltas, 3) float32
    """
    dense = np.asarray(dense)
    offsets = [0]
    indices, values = [], []
    for shape in dense:
        moved = np.flatnonzero(np.linalg.norm(shape, axis=1) > tolerance)
        indices.append(moved.astype(np.uint32))
        values.append(shape[moved].astype(np.float32))
        offsets.append(offsets[-1] + len(moved))
    return (
        np.asarray(offsets, dtype=np.int64),
        np.concatenate(indices) if indices else np.zeros(0, np.uint32),
        np.concatenate(values) if values else np.zeros((0, 3), np.float32),
    )
