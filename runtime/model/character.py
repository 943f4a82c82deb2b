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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.files.tables import (
    Section,
    TableSchema,
    TablesError,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)
from facepuppet.runtime.model.character_parts import (
    PART_CHANNELS,
    PART_SECTIONS,
    Expressions,
    Layout,
    Look,
    Skeleton,
    check_normals,
)
from facepuppet.runtime.model.geometry import vertex_normals
from facepuppet.runtime.model.look_at import look_at_of
from facepuppet.runtime.model.springs import spring_rig

# Material kinds the shader knows (column 2 of ``material_params``). "occlusion" (a dark soft shadow over
# the eye, fading from the lids) and "film" (a thin wet see-through layer: lacrimal fluid, eye blend) are
# drawn blended over the finished surfaces; "hidden" is not drawn.
MATERIAL_KINDS = {"skin": 0, "eye": 1, "teeth": 2, "mouth": 3, "lashes": 4, "hidden": 5, "lips": 6,
                  "occlusion": 7, "film": 8}

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
            # glTF / VRM parts (runtime.character_parts), each all or nothing; absent for OBJ rigs.
            **{name: spec for part in PART_SECTIONS.values() for name, spec in part.items()},
        },
        channels=("shapes", "materials"),
        channel_dims={"shapes": "n_shapes", "materials": "n_materials",
                      **{group: dim for group, (_, dim) in PART_CHANNELS.items() if dim}},
        version=2,  # 2: the optional skeleton, look, expressions and layout parts
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
    metadata : dict, settings/metrics/input hash carried into the manifest; ``settings["source"]``
        says where a glTF/VRM character came from (format, VRM meta, the extension JSON kept for export)
    skeleton, look, expressions, layout : the optional parts a glTF / VRM avatar brings
        (:mod:`facepuppet.runtime.model.character_parts`); None for an OBJ rig
    normals : ndarray of shape (n_vertices, 3), float32, unit, the file's rest normals, or None (computed
        from the triangles, :meth:`rest_normals`)
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
    skeleton: Skeleton | None = None
    look: Look | None = None
    expressions: Expressions | None = None
    layout: Layout | None = None
    normals: np.ndarray | None = None

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
        if self.skeleton is not None:
            self.skeleton.check(n_v)
        if self.look is not None:
            self.look.check(n_v, len(self.material_names))
        if self.expressions is not None:
            self.expressions.check(self.n_shapes)
        if self.layout is not None:
            self.layout.check(n_v, len(self.triangles), len(self.material_names))
        if self.normals is not None:
            check_normals(self.normals, n_v)
        if self.skeleton is not None:  # the spring bones and look-at a VRM brings (settings JSON), checked once
            settings = self.metadata.get("settings", {})
            if settings.get("springs") is not None:
                spring_rig(settings["springs"], self.skeleton.parent, self.skeleton.global_transforms())
            look_at_of(settings, self.skeleton.n_nodes)
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
            **self._part_arrays(),
        }

    def _part_arrays(self) -> dict[str, np.ndarray]:
        out = {}
        if (k := self.skeleton) is not None:
            out.update(node_parent=k.parent, node_rest=k.rest_local, vertex_nodes=k.vertex_nodes,
                       vertex_weights=k.vertex_weights)
        if (lk := self.look) is not None:
            out.update(uv=lk.uv, material_base_color=lk.base_color, material_emissive=lk.emissive,
                       material_alpha=lk.alpha, material_shading=lk.shading, material_texture=lk.texture,
                       material_uv_transform=lk.uv_transform, texture_info=lk.texture_info,
                       texture_pixels=lk.texture_pixels)
        if (e := self.expressions) is not None:
            out.update(expression_offsets=e.offsets, expression_bind_shape=e.bind_shape,
                       expression_bind_weight=e.bind_weight, expression_flags=e.flags)
        if (lay := self.layout) is not None:
            out.update(primitives=lay.primitives)
        if self.normals is not None:
            out.update(vertex_normals=self.normals)
        return out

    def rest_normals(self) -> np.ndarray:
        """Rest normals (n_vertices, 3) float32: the file's own where it gave them, else area-weighted."""
        if self.normals is not None:
            return self.normals
        return vertex_normals(self.vertices, self.triangles).astype(np.float32)

    def _channels(self) -> dict[str, list[str]]:
        channels = {"shapes": list(self.shape_names), "materials": list(self.material_names)}
        if self.skeleton is not None:
            channels["nodes"] = list(self.skeleton.names)
        if self.look is not None:
            channels["textures"] = list(self.look.texture_names)
        if self.expressions is not None:
            channels["expressions"] = list(self.expressions.names)
        if self.layout is not None:
            channels["meshes"] = list(self.layout.mesh_names)
        return channels

    @property
    def n_expressions(self) -> int:
        return 0 if self.expressions is None else self.expressions.n_expressions

    @property
    def source(self) -> Mapping[str, Any]:
        """Where a glTF/VRM character came from (``settings["source"]``: format, meta, …); {} for others."""
        return self.metadata.get("settings", {}).get("source", {})

    @property
    def credits(self) -> str:
        """The attribution its licence asks for (VRM meta / glTF asset), one line; "" when none is known."""
        return str(self.source.get("credits", ""))

    def with_parts(self, **changes: Any) -> Character:
        """A copy with some fields replaced (``dataclasses.replace``; validated again)."""
        return replace(self, **changes)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the character as a tables file of kind ``character``."""
        settings = dict(self.metadata.get("settings", {}))
        settings.setdefault("name", self.name)
        parts = {}
        if self.skeleton is not None:
            parts["bones"] = dict(self.skeleton.bones)
        if self.expressions is not None:
            parts["expression_presets"] = list(self.expressions.presets)
        if parts:
            settings["parts"] = parts
        else:
            settings.pop("parts", None)
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
                **_load_parts(a, t.channels, t.settings.get("parts", {})),
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


def _load_parts(a: Mapping[str, np.ndarray], channels: Mapping[str, list], parts: Mapping[str, Any]) -> dict:
    """The optional parts present in loaded arrays; a part with only some of its sections is refused."""
    out: dict[str, Any] = {}
    for part, sections in PART_SECTIONS.items():
        have = [name for name in sections if name in a]
        if not have:
            continue
        if len(have) != len(sections):
            missing = sorted(set(sections) - set(have))
            _fail(missing[0], f"missing: the {part} part has {', '.join(have)} but not {', '.join(missing)}")
        if part == "normals":
            out["normals"] = a["vertex_normals"]
            continue
        group = next(g for g, (p, _) in PART_CHANNELS.items() if p == part)
        if group not in channels:
            _fail(f"channels.{group}", f"missing: the {part} part needs its name list")
        names = tuple(channels[group])
        if part == "skeleton":
            bones = parts.get("bones", {})
            if not isinstance(bones, Mapping):
                _fail("settings.parts.bones", "must be an object of bone name -> node index")
            out["skeleton"] = Skeleton(names, a["node_parent"], a["node_rest"], a["vertex_nodes"],
                                       a["vertex_weights"], dict(bones))
        elif part == "look":
            out["look"] = Look(a["uv"], a["material_base_color"], a["material_emissive"], a["material_alpha"],
                               a["material_shading"], a["material_texture"], a["material_uv_transform"],
                               names, a["texture_info"], a["texture_pixels"])
        elif part == "expressions":
            presets = parts.get("expression_presets", [""] * len(names))
            if not (isinstance(presets, list) and all(isinstance(p, str) for p in presets)):
                _fail("settings.parts.expression_presets", "must be a list of strings")
            out["expressions"] = Expressions(names, tuple(presets), a["expression_offsets"],
                                             a["expression_bind_shape"], a["expression_bind_weight"],
                                             a["expression_flags"])
        else:
            out["layout"] = Layout(names, a["primitives"])
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
