"""VRM 0.x spring bones (``secondaryAnimation``): kept from the file on import, written back remapped.

The character does not simulate them; an export to VRM 0.x from a VRM 0.x
writes the bone groups and collider groups back with their nodes remapped
through ``settings.source.node_from_file``. A collider group whose node is
not in the character is dropped (and the bone groups' references to it); a
bone group keeps the bones that are, and is dropped with none. VRM 1.0's
``VRMC_springBone`` is a separate extension, not written.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from facepuppet.offline.io.gltf.write_state import WriteState


def write_spring_bones0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``secondaryAnimation`` (empty groups when none was kept)."""
    vrm["secondaryAnimation"] = _secondary0(w, raw.get("secondaryAnimation"), w.node_map())


def _secondary0(w: WriteState, raw: Any, remap: Callable[[Any], int | None]) -> dict:
    if not isinstance(raw, dict):
        return {"boneGroups": [], "colliderGroups": []}
    colliders, new_index = [], {}
    for k, g in enumerate(raw.get("colliderGroups", []) if isinstance(raw.get("colliderGroups"), list) else []):
        node = remap(g.get("node")) if isinstance(g, dict) else None
        if node is None:
            w.warn(f"secondaryAnimation.colliderGroups[{k}] dropped: its node is not in the character")
            continue
        new_index[k] = len(colliders)
        colliders.append({**g, "node": node})
    groups = []
    for k, g in enumerate(raw.get("boneGroups", []) if isinstance(raw.get("boneGroups"), list) else []):
        if not isinstance(g, dict):
            continue
        bones = [remap(b) for b in g.get("bones", []) if remap(b) is not None]
        if not bones:
            w.warn(f"secondaryAnimation.boneGroups[{k}] dropped: none of its bones is in the character")
            continue
        centre = g.get("center", -1)
        g = {**g, "bones": bones, "center": remap(centre) if remap(centre) is not None else -1,
             "colliderGroups": [new_index[i] for i in g.get("colliderGroups", []) if i in new_index]}
        groups.append(g)
    return {**raw, "boneGroups": groups, "colliderGroups": colliders}
