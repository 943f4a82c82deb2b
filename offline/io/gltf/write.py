"""A character back out as glTF 2.0 (GLB or .gltf) or VRM 0.x / 1.0 (``export-character``).

The export is the core glTF first, then the extensions. The core steps write
what any glTF 2.0 viewer reads: the skeleton's nodes, the meshes' host nodes
and the skin (:mod:`.write_nodes`), the meshes with their attributes and
morph targets (:mod:`.write_meshes`), the materials and textures
(:mod:`.write_materials`), all in one binary buffer (:mod:`.write_buffer`).
Then the writers of :data:`MATERIAL_EXTENSION_WRITERS` add the material
extensions (KHR_texture_transform, KHR_materials_unlit, VRM 1.0's
VRMC_materials_mtoon), and for a VRM the parts of :data:`VRM0_PARTS` or
:data:`VRM1_PARTS`, in their order, make the ``VRM`` / ``VRMC_vrm`` extension
object: meta, humanoid, first person and look-at, expressions (with a custom
expression per ARKit-named shape, for perfect sync), and in 0.x the spring
bones and material properties; a VRM 1.0's spring bones are the document's
``VRMC_springBone``. What the file had beyond the character's own parts comes
back from ``settings.source.kept`` (:mod:`.kept_parts`), converted when the
VRM version changes.

Frame: glTF units are metres (cm and mm are scaled); a VRM 0.x file faces
−Z, so for VRM 0.x output everything is turned 180° about +Y (vertices,
normals, deltas; the node transforms by turning the roots, so that every
world transform becomes ``T·G``, the inverse of the reader's turn).
"""

from __future__ import annotations

import base64
import json
import os
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.files.outputs import atomic_path
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.geometry import vertex_normals
from facepuppet.runtime.render.layers import has_layers, vertex_opacity

from facepuppet.offline.io.gltf import (
    khr_materials,
    vrm_expressions,
    vrm_first_person,
    vrm_humanoid,
    vrm_materials,
    vrm_meta,
    vrm_spring_bone,
)
from facepuppet.offline.io.gltf.write_materials import write_materials
from facepuppet.offline.io.gltf.write_meshes import plan_meshes, write_meshes
from facepuppet.offline.io.gltf.write_nodes import place_meshes, plan_hosts, rigid_frames, write_nodes, write_skin
from facepuppet.offline.io.gltf.write_state import GENERATOR, ExportError, ExportSummary, Progress, WriteState

__all__ = ["ExportError", "ExportSummary", "build_gltf", "encode_glb", "export_character", "output_format"]

GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}

#: The material extension writers, applied in this order to the core materials.
MATERIAL_EXTENSION_WRITERS: tuple[Callable[[WriteState, list[dict]], None], ...] = (
    khr_materials.write_texture_transform,
    khr_materials.write_unlit,
    vrm_materials.write_mtoon,
)
VrmPart = Callable[[WriteState, dict, dict[str, Any]], None]
#: The parts of VRM 0.x's ``VRM`` extension object, written in this order.
VRM0_PARTS: tuple[VrmPart, ...] = (
    vrm_meta.write_meta0,
    vrm_humanoid.write_humanoid0,
    vrm_first_person.write_first_person0,
    vrm_expressions.write_expressions0,
    vrm_spring_bone.write_spring_bones0,
    vrm_materials.write_material_properties,
)
#: The parts of VRM 1.0's ``VRMC_vrm`` extension object, written in this order.
VRM1_PARTS: tuple[VrmPart, ...] = (
    vrm_meta.write_meta1,
    vrm_humanoid.write_humanoid1,
    vrm_first_person.write_first_person1,
    vrm_expressions.write_expressions1,
)


def output_format(path: str | os.PathLike, character: Character, vrm: int | None = None) -> str:
    """"glb", "gltf", "vrm0" or "vrm1" from the output suffix (and ``vrm`` for a .vrm)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".vrm":
        if vrm is None:
            vrm = 1 if character.source.get("format") == "vrm1" else 0
        if vrm not in (0, 1):
            raise ExportError(f"--vrm {vrm}: VRM versions are 0 (0.x) and 1 (1.0)")
        return f"vrm{vrm}"
    if vrm is not None:
        raise ExportError(f"--vrm {vrm}: only for a .vrm output, not {Path(path).name}")
    if suffix in (".glb", ".gltf"):
        return suffix[1:]
    raise ExportError(f"{path}: unknown output format {suffix or '(no suffix)'}; name a .vrm, .glb or .gltf file")


def export_character(character: Character, path: str | os.PathLike, *, vrm: int | None = None,
                     progress: Progress | None = None) -> ExportSummary:
    """Write ``character`` to ``path`` (.glb, .gltf or .vrm, see :func:`output_format`), atomically."""
    start = time.perf_counter()
    path = Path(path)
    fmt = output_format(path, character, vrm)
    doc, blob, summary = build_gltf(character, fmt, progress=progress)
    summary.path = path
    if fmt == "gltf":
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        data = json.dumps(doc, ensure_ascii=False, indent=1).encode("utf-8")
    else:
        data = encode_glb(doc, blob)
    with atomic_path(path) as temp:
        temp.write_bytes(data)
    summary.bytes = len(data)
    summary.seconds = time.perf_counter() - start
    return summary


def encode_glb(doc: dict, blob: bytes) -> bytes:
    """A GLB: 12-byte header, JSON chunk padded with spaces, BIN chunk padded with zeros (4-byte aligned)."""
    js = json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(js), GLB_JSON) + js
    if blob:
        chunks += struct.pack("<II", len(blob), GLB_BIN) + blob
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def build_gltf(character: Character, fmt: str, *,
               progress: Progress | None = None) -> tuple[dict, bytes, ExportSummary]:
    """The glTF JSON document, its binary buffer and a summary for ``character`` in ``fmt``
    ("glb", "gltf", "vrm0", "vrm1"); see the module doc for what goes where."""
    if fmt not in ("glb", "gltf", "vrm0", "vrm1"):
        raise ExportError(f"unknown export format {fmt!r}")
    turn = fmt == "vrm0"
    w = WriteState(character, fmt, progress, turn=turn, summary=ExportSummary(Path(), fmt, turned_y180=turn))
    doc, blob = _build(w)
    return doc, blob, w.summary


def _build(w: WriteState) -> tuple[dict, bytes]:
    c = w.c
    if w.fmt.startswith("vrm"):  # refused before any work
        vrm_humanoid.check_humanoid(c)
    _vertex_data(w)
    doc: dict[str, Any] = {"asset": _asset(c), "scene": 0}
    nodes = write_nodes(w)
    plan_meshes(w)
    plan_hosts(w)
    rigid_frames(w)
    materials, textures = write_materials(w)
    for writer in MATERIAL_EXTENSION_WRITERS:
        writer(w, materials)
    meshes = write_meshes(w)
    place_meshes(w, nodes, len(meshes))
    roots = [j for j in range(w.n_skeleton_nodes) if c.skeleton.parent[j] < 0] if c.skeleton else []
    doc["scenes"] = [{"nodes": roots + list(range(w.n_skeleton_nodes, len(nodes)))}]
    doc["nodes"] = nodes
    doc["meshes"] = meshes
    if c.skeleton is not None and w.joints is not None:
        doc["skins"] = [write_skin(w)]
    doc["materials"] = materials
    doc.update(textures)
    if w.fmt == "vrm0":
        doc["extensions"] = {"VRM": _vrm_object(w, {"exporterVersion": GENERATOR, "specVersion": "0.0"}, VRM0_PARTS)}
        w.ext_used.add("VRM")
    elif w.fmt == "vrm1":
        doc["extensions"] = {"VRMC_vrm": _vrm_object(w, {"specVersion": "1.0"}, VRM1_PARTS)}
        w.ext_used.add("VRMC_vrm")
        spring = vrm_spring_bone.spring_bone1(w, nodes)  # may add the tail nodes of VRM 0.x leaves
        if spring is not None:
            doc["extensions"]["VRMC_springBone"] = spring
            w.ext_used.add("VRMC_springBone")
    doc["accessors"] = w.buf.accessors
    doc["bufferViews"] = w.buf.views
    blob = w.buf.data()
    doc["buffers"] = [{"byteLength": len(blob)}]
    if w.ext_used:
        doc["extensionsUsed"] = sorted(w.ext_used)
    s = w.summary
    s.n_meshes, s.n_nodes, s.n_materials = len(meshes), len(nodes), len(materials)
    doc["scenes"] = [{"nodes": [j for j in doc["scenes"][0]["nodes"] if j not in _child_nodes(nodes)]}]
    s.n_primitives = sum(len(m["primitives"]) for m in meshes)
    return {k: v for k, v in doc.items() if v != [] or k in ("buffers",)}, blob


def _child_nodes(nodes: list[dict]) -> set[int]:
    return {c for n in nodes for c in n.get("children", [])}


def _vrm_object(w: WriteState, out: dict[str, Any], parts: tuple[VrmPart, ...]) -> dict[str, Any]:
    """The VRM extension object: ``out`` with each part written into it, in order, from the kept extension."""
    raw = w.kept_vrm()
    for part in parts:
        part(w, raw, out)
    return out


def _vertex_data(w: WriteState) -> None:
    """The vertices, normals, morph deltas (and an OBJ rig's layer fade) in the file's units and frame."""
    c = w.c
    scale = _UNIT_SCALE.get(c.units)
    if scale is None:
        raise ExportError(f"character {c.name!r}: units {c.units!r} are not m, cm or mm")
    w.scale = scale
    w.vertices = w.points(c.vertices, scale)
    if c.normals is not None:  # the file's own normals (hard edges, custom normals), turned as the points
        w.normals = w.points(c.normals)
    else:
        w.normals = vertex_normals(w.vertices, c.triangles.astype(np.int64))
    no_normal = np.linalg.norm(w.normals, axis=1) < 0.5
    w.normals[no_normal] = (0.0, 0.0, -1.0 if w.turn else 1.0)
    # an OBJ rig's thin layers: the fade the renderer gives them, as COLOR_0 alpha
    w.opacity = vertex_opacity(c).astype(np.float32) if c.look is None and has_layers(c) else None
    w.delta_pos = w.points(c.delta_positions, scale)
    w.delta_nrm = w.points(c.delta_normals)


def _asset(c: Character) -> dict:
    """glTF ``asset``: version and generator; a plain glTF's copyright and its title, author, licence and source
    (in ``extras``) as the reader kept them."""
    asset = {"version": "2.0", "generator": GENERATOR}
    meta = c.source.get("meta", {}) if isinstance(c.source.get("meta"), dict) else {}
    if c.source.get("format") in ("gltf", "glb", None):
        if isinstance(meta.get("copyright"), str):
            asset["copyright"] = meta["copyright"]
        extras = {k: meta[k] for k in ("title", "author", "license", "source") if isinstance(meta.get(k), str)}
        if extras:
            asset["extras"] = extras
    return asset


def describe(summary: ExportSummary) -> str:
    """The command's summary of an export, a few lines."""
    s = summary
    lines = [f"{s.path}: {s.format.upper()}, {s.bytes / 1e6:.2f} MB, {s.seconds:.2f} s"
             + (" (turned 180° about +Y: VRM 0.x faces -Z)" if s.turned_y180 else ""),
             f"  {s.n_meshes} meshes, {s.n_primitives} primitives, {s.n_nodes} nodes ({s.n_joints} joints), "
             f"{s.n_materials} materials, {s.n_textures} textures",
             f"  morph targets: {s.n_targets} ({s.n_sparse_targets} sparse)"]
    if s.format.startswith("vrm"):
        added = f", {len(s.added_expressions)} added for perfect sync" if s.added_expressions else ""
        lines.append(f"  expressions: {s.n_expressions}{added}")
        if s.n_springs:
            lines.append(f"  springs: {s.n_springs}")
    lines += [f"  warning: {w}" for w in s.warnings]
    return "\n".join(lines)
