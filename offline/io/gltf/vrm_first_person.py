"""VRM first person and look-at: kept from the file on import, written back onto the written nodes.

The reader keeps these parts raw (``settings.source.vrm_extension``); an
export to the VRM version the character came from writes them back with node
indices remapped through ``settings.source.node_from_file``, and the
first-person mesh annotations through ``mesh_nodes`` / ``mesh_from_file``
when the reader kept them (dropped with a warning otherwise). A VRM 0.x
without a first-person bone gets the head bone, offset 6 cm up. (VRM 0.x
keeps its look-at settings inside ``firstPerson``; VRM 1.0 has ``lookAt`` of
its own, written as it was.)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from facepuppet.offline.io.gltf.write_state import WriteState


def write_first_person0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``firstPerson``: the kept one, its bone remapped (the head when it is not in the character), its
    mesh annotations onto the written meshes; else the head bone with its offset."""
    head = int(w.c.skeleton.bones["head"])
    remap = w.node_map()
    first = raw.get("firstPerson") if isinstance(raw.get("firstPerson"), dict) else {}
    if "firstPersonBone" in first:
        node = remap(first["firstPersonBone"])
        first["firstPersonBone"] = node if node is not None else head
    else:
        first.setdefault("firstPersonBone", head)
        first.setdefault("firstPersonBoneOffset", {"x": 0.0, "y": 0.06, "z": 0.0})
    first["meshAnnotations"] = _annotations0(w, first.get("meshAnnotations"))
    vrm["firstPerson"] = first


def write_first_person1(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 1.0 ``firstPerson`` (its mesh annotations onto the nodes holding the written meshes) and ``lookAt``,
    as kept."""
    first = raw.get("firstPerson")
    if isinstance(first, dict):
        annotations = _annotations1(w, first.get("meshAnnotations"), w.node_map())
        vrm["firstPerson"] = {**first, "meshAnnotations": annotations}
    if isinstance(raw.get("lookAt"), dict):
        vrm["lookAt"] = raw["lookAt"]


def _annotations0(w: WriteState, raw: Any) -> list:
    """VRM 0.x firstPerson.meshAnnotations ({mesh: file mesh index}) onto the written meshes, through
    ``settings.source.mesh_from_file`` (the file mesh of each Layout mesh) when the reader kept it."""
    if not isinstance(raw, list) or not raw:
        return []
    of_file = w.c.source.get("mesh_from_file")
    if not (isinstance(of_file, list) and len(of_file) == len(w.mesh_names)):
        w.warn("firstPerson.meshAnnotations dropped: the character does not keep which file mesh each "
               "of its meshes was (VRM applications then use their automatic first-person view)")
        return []
    out = []
    for a in raw:
        if isinstance(a, dict):
            out += [{**a, "mesh": m} for m, f in enumerate(of_file) if f == a.get("mesh")]
    return out


def _annotations1(w: WriteState, raw: Any, remap: Callable[[Any], int | None]) -> list:
    """VRM 1.0 firstPerson.meshAnnotations ({node: file node}) onto the nodes the meshes are written on."""
    if not isinstance(raw, list):
        return []
    out = []
    for a in raw:
        node = remap(a.get("node")) if isinstance(a, dict) else None
        if node is not None and node in w.host:
            out.append({**a, "node": node})
        else:
            w.warn(f"firstPerson.meshAnnotations: {a!r} dropped: its node does not hold a written mesh "
                   "(the reader did not keep settings.source.mesh_nodes)")
    return out
