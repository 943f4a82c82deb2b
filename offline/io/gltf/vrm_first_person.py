"""VRM first person and look-at: kept from the file on import, written back onto the written nodes.

The reader keeps these parts raw (``settings.source.vrm_extension``); an
export to the VRM version the character came from writes them back with node
indices remapped through ``settings.source.node_from_file``, and the
first-person mesh annotations through ``mesh_nodes`` / ``mesh_from_file``
when the reader kept them (dropped with a warning otherwise). A VRM 0.x
without a first-person bone gets the head bone, offset 6 cm up. VRM 0.x
keeps its look-at settings inside ``firstPerson``; VRM 1.0 has ``lookAt`` of
its own. Between the versions they are converted as the VRM migration does:
the offset (0.x from the first-person bone, in Unity's axes; 1.0 from the
head, in glTF's, both facing +Z) reverses x; ``lookAtTypeName`` Bone /
BlendShape is type bone / expression; each 0.x curve map's ``xRange`` /
``yRange`` is a 1.0 range map's ``inputMaxValue`` / ``outputScale`` (1.0 maps
linearly: a 0.x curve rides along in the range map's ``extras.vrm0Curve``,
for the way back, and a 1.0 map without one goes back as the linear curve);
the mesh annotations' flags (``ThirdPersonOnly`` / ``thirdPersonOnly``)
move from the file's meshes to the nodes that hold them and back.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from facepuppet.offline.io.gltf.write_state import WriteState

_MAPS = (("lookAtHorizontalInner", "rangeMapHorizontalInner"), ("lookAtHorizontalOuter", "rangeMapHorizontalOuter"),
         ("lookAtVerticalDown", "rangeMapVerticalDown"), ("lookAtVerticalUp", "rangeMapVerticalUp"))
_LINEAR_CURVE = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0]  # Unity keyframes (time, value, in, out): y = x


def write_first_person0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``firstPerson``: the kept one, its bone remapped (the head when it is not in the character), its
    mesh annotations onto the written meshes; converted from a VRM 1.0's first person and look-at; else the
    head bone with its offset."""
    head = int(w.c.skeleton.bones["head"])
    remap = w.node_map()
    first = raw.get("firstPerson") if isinstance(raw.get("firstPerson"), dict) else {}
    if w.c.source.get("format") == "vrm1":
        vrm["firstPerson"] = _first_person0_from_1(w, head)
        return
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
    as kept, or converted from a VRM 0.x's."""
    src = w.c.source
    if src.get("format") == "vrm0":
        _first_person1_from_0(w, vrm)
        return
    first = raw.get("firstPerson")
    if isinstance(first, dict):
        annotations = _annotations1(w, first.get("meshAnnotations"), w.node_map())
        vrm["firstPerson"] = {**first, "meshAnnotations": annotations}
    if isinstance(raw.get("lookAt"), dict):
        vrm["lookAt"] = raw["lookAt"]


def _vrm_raw(w: WriteState) -> dict:
    raw = w.c.source.get("vrm_extension")
    return raw if isinstance(raw, dict) else {}


def _first_person1_from_0(w: WriteState, vrm: dict[str, Any]) -> None:
    """VRM 1.0 ``firstPerson`` and ``lookAt`` from a VRM 0.x's ``firstPerson`` (see the module doc)."""
    first = _vrm_raw(w).get("firstPerson")
    if not isinstance(first, dict):
        return
    annotations = []
    for a in _annotations0(w, first.get("meshAnnotations")):
        flag = a.get("firstPersonFlag")
        if isinstance(flag, str) and flag and 0 <= a["mesh"] < len(w.host):
            annotations.append({"node": w.host[a["mesh"]], "type": flag[0].lower() + flag[1:]})
    vrm["firstPerson"] = {"meshAnnotations": annotations}
    o = first.get("firstPersonBoneOffset") if isinstance(first.get("firstPersonBoneOffset"), dict) else {}
    look: dict[str, Any] = {"offsetFromHeadBone": [0.0 - _num(o.get("x"), 0.0), _num(o.get("y"), 0.06),
                                                   _num(o.get("z"), 0.0)],
                            "type": "expression" if first.get("lookAtTypeName") == "BlendShape" else "bone"}
    for key0, key1 in _MAPS:
        m = first.get(key0)
        if isinstance(m, dict):
            look[key1] = {"inputMaxValue": _num(m.get("xRange"), 90.0), "outputScale": _num(m.get("yRange"), 10.0)}
            if _curve(m.get("curve")) and m["curve"] != _LINEAR_CURVE:  # 1.0 maps linearly: the curve rides along
                look[key1]["extras"] = {"vrm0Curve": [float(x) for x in m["curve"]]}
    vrm["lookAt"] = look


def _first_person0_from_1(w: WriteState, head: int) -> dict:
    """VRM 0.x ``firstPerson`` (with its look-at) from a VRM 1.0's ``firstPerson`` and ``lookAt``."""
    raw = _vrm_raw(w)
    remap = w.node_map()
    out: dict[str, Any] = {"firstPersonBone": head}
    first = raw.get("firstPerson") if isinstance(raw.get("firstPerson"), dict) else {}
    annotations = []
    for a in _annotations1(w, first.get("meshAnnotations"), remap):
        kind = a.get("type")
        if isinstance(kind, str) and kind:
            annotations += [{"mesh": m, "firstPersonFlag": kind[0].upper() + kind[1:]}
                            for m, h in enumerate(w.host) if h == a["node"]]
    out["meshAnnotations"] = annotations
    look = raw.get("lookAt") if isinstance(raw.get("lookAt"), dict) else {}
    o = look.get("offsetFromHeadBone")
    o = o if isinstance(o, list) and len(o) == 3 else [0.0, 0.06, 0.0]
    out["firstPersonBoneOffset"] = {"x": 0.0 - _num(o[0], 0.0), "y": _num(o[1], 0.06), "z": _num(o[2], 0.0)}
    if look:
        out["lookAtTypeName"] = "BlendShape" if look.get("type") == "expression" else "Bone"
        for key0, key1 in _MAPS:
            m = look.get(key1)
            if isinstance(m, dict):
                extras = m.get("extras") if isinstance(m.get("extras"), dict) else {}
                curve = extras.get("vrm0Curve") if _curve(extras.get("vrm0Curve")) else list(_LINEAR_CURVE)
                out[key0] = {"curve": curve, "xRange": _num(m.get("inputMaxValue"), 90.0),
                             "yRange": _num(m.get("outputScale"), 10.0)}
    return out


def _curve(v: Any) -> bool:
    """A 0.x look-at curve: Unity keyframes, four numbers each (time, value, in and out tangents)."""
    return isinstance(v, list) and len(v) % 4 == 0 and 0 < len(v) <= 256 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)


def _num(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else default


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
