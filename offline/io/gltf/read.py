"""glTF 2.0 / GLB / VRM 0.x / VRM 1.0 -> :class:`~facepuppet.runtime.model.character.Character` with its parts.

``read_gltf(path)`` reads the default scene and stores, as
:mod:`facepuppet.runtime.model.character_parts` asks: vertices, normals and morph
deltas in the rest pose in world space, metres, +Y up, facing +Z (a VRM 0.x
avatar faces −Z and is turned 180° about +Y); the node hierarchy renumbered
parents first; per vertex four (node, weight) pairs (a mesh without a skin
follows its own node at weight 1); materials and base colour textures; VRM
humanoid bones, expressions and meta.

The read is the core glTF first, then the extensions. The core steps read
what every glTF 2.0 file has: the nodes (:mod:`.read_nodes`), the meshes,
skins and morph targets (:mod:`.read_meshes`), the materials and textures
(:mod:`.read_materials`). Then each reader of :data:`EXTENSION_READERS`, in
its order, adds what one extension or one VRM concept says (material
extensions change the look rows; the VRM readers give the humanoid, the
expressions and the meta). A file that requires an extension no reader
honours is refused; one that only uses it is read with a warning.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facepuppet.runtime.files.tables import TablesError, hash_inputs, naming_file
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import Layout, Look, Skeleton

from facepuppet.offline.io.gltf import khr_materials, vrm_expressions, vrm_humanoid, vrm_materials, vrm_meta
from facepuppet.offline.io.gltf.credits import credit_line, text
from facepuppet.offline.io.gltf.read_look_at import read_look_at
from facepuppet.offline.io.gltf.read_materials import read_materials
from facepuppet.offline.io.gltf.read_meshes import Progress, read_geometry, read_shapes
from facepuppet.offline.io.gltf.read_nodes import read_nodes
from facepuppet.offline.io.gltf.read_springs import read_springs
from facepuppet.offline.io.gltf.read_state import ReadState, extensions_of
from facepuppet.offline.io.gltf.structure_limits import check_kept_json, check_structure
from facepuppet.offline.io.gltf_container import GltfError, GltfFile, read_gltf_file

__all__ = ["read_gltf", "EXTENSION_READERS", "SUPPORTED_EXTENSIONS", "GltfError"]


@dataclass(frozen=True)
class ExtensionReader:
    """Reads one extension, or one VRM concept, into a read whose core glTF is done."""

    extensions: tuple[str, ...]  # the extension names it honours (so a file may require them)
    read: Callable[[ReadState], None]


#: The extension readers, applied in this order after the core glTF. The VRM 0.x material properties come
#: before VRMC_materials_mtoon, which wins on a material that has both; the expressions before the humanoid,
#: so that their warnings come in the file's order of concepts.
EXTENSION_READERS: tuple[ExtensionReader, ...] = (
    ExtensionReader(("KHR_materials_emissive_strength",), khr_materials.read_emissive_strength),
    ExtensionReader(("KHR_materials_unlit",), khr_materials.read_unlit),
    ExtensionReader(("KHR_texture_transform",), khr_materials.read_texture_transform),
    ExtensionReader(("VRM",), vrm_materials.read_material_properties),
    ExtensionReader(("VRMC_materials_mtoon",), vrm_materials.read_mtoon),
    ExtensionReader(("VRM", "VRMC_vrm"), vrm_expressions.read_expressions),
    ExtensionReader(("VRM", "VRMC_vrm"), vrm_humanoid.read_humanoid),
    ExtensionReader(("VRM", "VRMC_vrm"), vrm_meta.read_meta),
    ExtensionReader(("VRM", "VRMC_springBone"), read_springs),
    ExtensionReader(("VRM", "VRMC_vrm"), read_look_at),  # after the humanoid: the eye bones
)
#: Extensions whose meaning the reader honours (may be required): KHR_mesh_quantization is plain accessor
#: decoding (:mod:`facepuppet.offline.io.gltf_container`), the others have their reader.
SUPPORTED_EXTENSIONS = frozenset({"KHR_mesh_quantization"}).union(*(r.extensions for r in EXTENSION_READERS))
#: Used-only extensions that carry nothing the character needs (no warning): VRM's constraints and animation
#: are kept in the raw VRM JSON for export.
QUIET_EXTENSIONS = frozenset({"VRMC_node_constraint", "VRMC_vrm_animation"})
#: The fields of ``asset`` and of ``asset.extras`` a plain glTF's character keeps as its meta.
_ASSET_META = ("copyright", "generator", "version")
_EXTRAS_META = ("title", "author", "license", "source")


def read_gltf(path: str | os.PathLike, *, name: str | None = None, progress: Progress | None = None) -> Character:
    """Read a glTF 2.0 (``.gltf``), GLB (``.glb``) or VRM (``.vrm``) file as a character with its parts.

    Parameters
    ----------
    path : the file; the format is found from its bytes (GLB magic ``glTF``, else JSON)
    name : character name; default the VRM title, else the file stem
    progress : callable(i, n, label) after each mesh instance is read, i from 1

    Returns
    -------
    Character, units "m", with skeleton, look, expressions (VRM only) and layout; ``metadata``
    holds ``settings["source"]`` (format, meta, credits, warnings, node_from_file, …) and metrics.

    Raises
    ------
    GltfError
        (an InputFileError) naming the file and the JSON field path: bad container, bad or
        out-of-range data, unsupported required extension, primitive mode other than triangles, a
        structure past the limits of :mod:`.structure_limits` (refused before any accessor is decoded).
    FileNotFoundError
        the file is missing.
    """
    f = read_gltf_file(Path(path))
    with np.errstate(all="ignore"):  # overflow shows as non-finite values, refused by name below
        check_structure(f)
        state = _new_state(f)
        _check_kept(state)
        _check_extensions(state)
        read_nodes(state)
        read_geometry(state, progress)
        read_materials(state)
        read_shapes(state)
        _asset_meta(state)
        for reader in EXTENSION_READERS:
            reader.read(state)
        return _character(state, name)


def _new_state(f: GltfFile) -> ReadState:
    """The read of ``f`` with its format: VRM 1.0 when it has ``VRMC_vrm``, else VRM 0.x when it has ``VRM``,
    else GLB or glTF by its container; a VRM 0.x is turned to face +Z."""
    vrm0 = extensions_of(f.doc).get("VRM")
    vrm1 = extensions_of(f.doc).get("VRMC_vrm")
    if vrm0 is not None and not isinstance(vrm0, dict):
        f.fail("extensions.VRM", "expected an object")
    if vrm1 is not None and not isinstance(vrm1, dict):
        f.fail("extensions.VRMC_vrm", "expected an object")
    if vrm1 is not None:
        fmt = "vrm1"
    elif vrm0 is not None:
        fmt = "vrm0"
    else:
        fmt = "glb" if f.is_glb else "gltf"
    return ReadState(f=f, format=fmt, vrm0=vrm0, vrm1=vrm1, turn=fmt == "vrm0")


def _check_kept(state: ReadState) -> None:
    """What the character keeps of the file's JSON as it came (the VRM extension, the asset's meta fields) within
    :data:`~.structure_limits.MAX_KEPT_JSON_DEPTH` and finite, refused here by its path in the file."""
    f = state.f
    if state.vrm1 is not None:
        check_kept_json(f, state.vrm1, "extensions.VRMC_vrm")
    elif state.vrm0 is not None:
        check_kept_json(f, state.vrm0, "extensions.VRM")
    asset = state.doc.get("asset", {})
    extras = asset.get("extras")
    for key in _ASSET_META:
        if key in asset:
            check_kept_json(f, asset[key], f"asset.{key}", 2)
    for key in _EXTRAS_META:
        if isinstance(extras, dict) and key in extras:
            check_kept_json(f, extras[key], f"asset.extras.{key}", 2)


def _check_extensions(state: ReadState) -> None:
    f = state.f
    used = state.doc.get("extensionsUsed", [])
    required = state.doc.get("extensionsRequired", [])
    for key, value in (("extensionsUsed", used), ("extensionsRequired", required)):
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            f.fail(key, "expected an array of extension names")
    refused = [e for e in required if e not in SUPPORTED_EXTENSIONS]
    if refused:
        f.fail("extensionsRequired", f"{', '.join(refused)}: required by the file but not supported by this "
                                     f"reader (supported: {', '.join(sorted(SUPPORTED_EXTENSIONS))})")
    ignored = [e for e in used if e not in SUPPORTED_EXTENSIONS and e not in QUIET_EXTENSIONS]
    if ignored:
        state.warn(f"extensions used but not honoured (ignored): {', '.join(ignored)}")


def _asset_meta(state: ReadState) -> None:
    """The meta and credits of a plain glTF: the asset's copyright, generator and version, and the title,
    author, licence and source of its ``extras`` (a VRM's meta reader replaces them)."""
    asset = state.doc.get("asset", {})
    meta = {k: v for k, v in asset.items() if k in _ASSET_META}
    extras = asset.get("extras")
    if isinstance(extras, dict):
        meta.update({k: v for k, v in extras.items() if k in _EXTRAS_META})
    state.meta = meta
    state.credits = credit_line(text(meta, "title"), text(meta, "author"), text(meta, "license"),
                                text(meta, "copyright"))


def _character(state: ReadState, name: str | None) -> Character:
    """The character of a finished read: every array checked finite in float32, the pivot, the source."""
    f, geo, deltas, rows = state.f, state.geo, state.deltas, state.look
    look = Look(uv=geo["uv"].astype(np.float32), base_color=rows.base.astype(np.float32),
                emissive=rows.emissive.astype(np.float32), alpha=rows.alpha.astype(np.float32),
                shading=rows.shading.astype(np.float32), texture=rows.texture.astype(np.int32),
                uv_transform=rows.uv_transform.astype(np.float32), texture_names=state.texture_names,
                texture_info=state.texture_info, texture_pixels=state.texture_pixels)
    skeleton = Skeleton(tuple(state.node_names), state.parent.astype(np.int32), state.rest_local.astype(np.float32),
                        geo["vertex_nodes"].astype(np.uint16), geo["vertex_weights"].astype(np.float32),
                        state.bones)
    vertices = geo["vertices"]
    if not np.isfinite(vertices).all() or np.abs(vertices).max() > np.finfo(np.float32).max:
        f.fail("nodes", "the node transforms take vertices beyond the float32 range")
    for where, arr in (("morph targets", deltas["delta_positions"]), ("morph targets", deltas["delta_normals"]),
                       ("materials", look.base_color), ("materials", look.emissive), ("materials", look.alpha),
                       ("materials", look.shading), ("materials", look.uv_transform),
                       ("TEXCOORD_0", look.uv), ("COLOR_0", geo["colors"]),
                       ("skins", skeleton.rest_local), ("skins", skeleton.vertex_weights)):
        if not np.isfinite(arr).all():
            f.fail(where, "values beyond the float32 range (or NaN) after transforming; a character stores "
                          "finite float32")
    pivot, pivot_rule = _pivot(state, skeleton, vertices)
    meta = state.meta
    source = {
        "format": state.format,
        "file": f.path.name,
        "turned_y180": state.turn,
        "meta": meta,
        "credits": state.credits,
        "extensions_used": list(state.doc.get("extensionsUsed", [])),
        "vrm_extension": state.vrm0 if state.vrm0 is not None else state.vrm1,
        "node_from_file": [int(i) for i in state.node_from_file],
        "mesh_nodes": [int(s) for _, s in sorted(x for v in geo["instance_of_mesh"].values() for x in v)],
        "mesh_from_file": [m for _, m in sorted((mi, m) for m, v in geo["instance_of_mesh"].items()
                                                for mi, _ in v)],
        "default_weights": geo["default_weights"],
        "warnings": state.warnings,
        "pivot_rule": pivot_rule,
        "kept": state.kept,
    }
    if not isinstance(name, str) or not name:
        name = str(meta.get("title") or meta.get("name") or f.path.stem) or f.path.stem
    settings = {"source": source, "name": name}
    if state.springs.get("chains"):
        settings["springs"] = state.springs
    if state.look_at:
        settings["look_at"] = state.look_at
    expressions = state.expressions
    metrics = {"n_vertices": int(len(vertices)), "n_triangles": int(len(geo["triangles"])),
               "n_meshes": len(geo["mesh_names"]), "n_primitives": int(len(geo["primitives"])),
               "n_nodes": len(state.node_names), "n_joints": geo["n_joints"],
               "n_textures": len(look.texture_names),
               "n_expressions": len(expressions.names) if expressions is not None else 0,
               "stored_deltas": int(deltas["delta_offsets"][-1])}
    with naming_file(f.path):
        try:
            return Character(
                name=name, units="m",
                vertices=vertices.astype(np.float32),
                triangles=geo["triangles"].astype(np.uint32),
                triangle_material=geo["triangle_material"].astype(np.uint16),
                vertex_color=geo["colors"].astype(np.float32),
                material_names=state.material_names,
                material_params=state.material_params,
                pivot=pivot.astype(np.float32),
                shape_names=state.shape_names,
                **deltas,
                metadata={"settings": settings, "metrics": metrics,
                          "input_hash": hash_inputs(f.path, *f.external)},
                skeleton=skeleton, look=look,
                expressions=expressions,
                layout=Layout(tuple(geo["mesh_names"]), geo["primitives"]),
                normals=geo["normals"].astype(np.float32) if geo["file_normals"] else None,
            )
        except TablesError as exc:  # a value the file allows but a character cannot hold
            raise GltfError(f.path, exc.field, exc.problem) from None


def _pivot(state: ReadState, skeleton: Skeleton, vertices: np.ndarray) -> tuple[np.ndarray, str]:
    if "head" in skeleton.bones:
        return state.world[skeleton.bones["head"]][:3, 3].copy(), "the head bone's rest position"
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    size, centre = hi - lo, (hi + lo) / 2
    return (np.array([centre[0], lo[1] + 0.35 * size[1], centre[2] - 0.1 * size[2]]),
            "bbox: centre x, min y + 0.35 height, centre z - 0.1 depth")
