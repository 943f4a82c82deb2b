"""VRM humanoid: which node is each human bone, read into ``Skeleton.bones`` and written back.

VRM 0.x lists ``humanoid.humanBones`` as an array of {bone, node}; VRM 1.0 as
an object of bone name -> {node}. A bone whose node is not in the default
scene is dropped with a warning. A VRM is written only for a character whose
skeleton names the bones VRM requires (:data:`REQUIRED_BONES`); the 0.x
humanoid's other settings kept on import (arm stretch, …) go back with it.
"""

from __future__ import annotations

from typing import Any

from facepuppet.runtime.model.character import Character

from facepuppet.offline.io.gltf.read_state import ReadState
from facepuppet.offline.io.gltf.write_state import ExportError, WriteState

#: Humanoid bones VRM requires (1.0 spec, humanoid.md "required"; the same set satisfies UniVRM 0.x).
REQUIRED_BONES = ("hips", "spine", "head", "leftUpperLeg", "leftLowerLeg", "leftFoot", "rightUpperLeg",
                  "rightLowerLeg", "rightFoot", "leftUpperArm", "leftLowerArm", "leftHand", "rightUpperArm",
                  "rightLowerArm", "rightHand")


def read_humanoid(state: ReadState) -> None:
    """``state.bones``: {bone name: stored node} of a VRM's humanoid (nothing for a plain glTF)."""
    f = state.f
    bones: dict[str, int] = {}
    if state.vrm1 is not None:
        hb = state.vrm1.get("humanoid", {}).get("humanBones", {}) if isinstance(state.vrm1.get("humanoid"),
                                                                                dict) else {}
        w = "extensions.VRMC_vrm.humanoid.humanBones"
        if not isinstance(hb, dict):
            f.fail(w, "expected an object of bone name -> {node}")
        pairs = [(b, v.get("node") if isinstance(v, dict) else None, f"{w}.{b}.node") for b, v in hb.items()]
    elif state.vrm0 is not None:
        hb = state.vrm0.get("humanoid", {}).get("humanBones", []) if isinstance(state.vrm0.get("humanoid"),
                                                                                dict) else []
        w = "extensions.VRM.humanoid.humanBones"
        if not isinstance(hb, list):
            f.fail(w, "expected an array of {bone, node}")
        pairs = [(v.get("bone") if isinstance(v, dict) else None, v.get("node") if isinstance(v, dict) else None,
                  f"{w}[{k}]") for k, v in enumerate(hb)]
    else:
        return
    for bone, node, where in pairs:
        if not isinstance(bone, str) or not bone:
            f.fail(where, "a human bone needs a bone name")
        f.obj("nodes", node, where)
        if node not in state.stored_of:
            state.warn(f"{where}: bone {bone!r} is node {node}, which is not in the default scene (dropped)")
            continue
        bones[bone] = int(state.stored_of[node])
    state.bones = bones


def check_humanoid(c: Character) -> None:
    """Refuse, before anything is written, a VRM of a character without the humanoid bones VRM requires."""
    if c.skeleton is None:
        raise ExportError(f"character {c.name!r}: a VRM needs a humanoid skeleton and this character has none "
                          f"(it came from {c.source.get('format', 'an OBJ rig')}); missing bones: "
                          f"{', '.join(REQUIRED_BONES)}. Export it as .glb instead")
    missing = [b for b in REQUIRED_BONES if b not in c.skeleton.bones]
    if missing:
        raise ExportError(f"character {c.name!r}: a VRM humanoid needs the bones {', '.join(missing)}, which "
                          "the character's skeleton does not name; export it as .glb instead")


def write_humanoid0(w: WriteState, raw: dict, out: dict[str, Any]) -> None:
    """VRM 0.x ``humanoid``: the kept settings, the bones as {bone, node, useDefaultValues}."""
    humanoid = raw.get("humanoid") if isinstance(raw.get("humanoid"), dict) else {}
    humanoid = {k: v for k, v in humanoid.items() if k != "humanBones"}
    humanoid["humanBones"] = [{"bone": b, "node": int(n), "useDefaultValues": True}
                              for b, n in w.c.skeleton.bones.items()]
    out["humanoid"] = humanoid


def write_humanoid1(w: WriteState, raw: dict, out: dict[str, Any]) -> None:
    """VRM 1.0 ``humanoid``: bone name -> {node}."""
    out["humanoid"] = {"humanBones": {b: {"node": int(n)} for b, n in w.c.skeleton.bones.items()}}
