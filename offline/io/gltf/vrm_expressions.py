"""VRM expressions (0.x blend shape groups, 1.0 expressions): read into ``Expressions``, written back.

Read: each expression binds morph targets, named by (mesh, index) in 0.x and
(node, index) in 1.0, at weights 0..100 (0.x) or 0..1 (1.0); the target's
name finds the character's shape. 0.x preset names are kept in their 0.x
spelling (``Blink_L``); a 1.0 preset is read under the 0.x name it renames.
One shape spans every mesh whose targets share its name, so the binds of one
shape on several meshes are one bind. A bind naming no morph target of the
scene is dropped with a warning.

Written: the character's expressions (with the binds on materials the file
had, :mod:`.vrm_material_binds`), and a custom expression for each shape
whose name is one of ARKit's 52 and has no expression of its name yet
(perfect sync: ``EyeBlinkLeft`` …), each bound on every mesh that has the
shape.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from facepuppet.runtime.mapping.channels import ARKIT_NAMES, canonical, pascal
from facepuppet.runtime.mapping.vrm_names import VRM0_PRESETS, VRM1_FROM_VRM0
from facepuppet.runtime.model.character_parts import OVERRIDES, Expressions

from facepuppet.offline.io.gltf.read_state import ReadState, target_names
from facepuppet.offline.io.gltf.vrm_material_binds import material_binds, write_binds0, write_binds1
from facepuppet.offline.io.gltf.write_state import WriteState

_VRM0_BY_LOWER = {p.lower(): p for p in VRM0_PRESETS}
_VRM0_FROM_VRM1 = {v: k for k, v in VRM1_FROM_VRM0.items()}
_VRM1_PRESETS = frozenset(VRM1_FROM_VRM0.values()) | {"surprised"}
_ARKIT = frozenset(ARKIT_NAMES)
_OVERRIDE_NAME = {v: k for k, v in OVERRIDES.items()}


def read_expressions(state: ReadState) -> None:
    """``state.expressions`` of a VRM (0.x blend shape groups or 1.0 expressions; nothing for a plain glTF)."""
    shape_names = state.shape_names
    shape_index = {n: i for i, n in enumerate(shape_names)}
    if state.vrm1 is not None:
        rows = _vrm1_expressions(state, shape_index, _TargetNames(state))
    elif state.vrm0 is not None:
        rows = _vrm0_expressions(state, shape_index, _TargetNames(state))
    else:
        return
    names, presets, offsets, bs, bw, flags = [], [], [0], [], [], []
    seen: set[str] = set()
    for name, preset, shapes, weights, flag in rows:
        if name in seen:
            state.warn(f"expression {name!r} appears twice; the first is kept")
            continue
        seen.add(name)
        # One shape spans every mesh whose targets share its name, and VRM binds it once per mesh:
        # the binds of one shape are one bind (the largest, with a warning when the meshes differ).
        merged: dict[int, float] = {}
        for s, wt in zip(shapes, weights):
            if s in merged and abs(merged[s] - wt) > 1e-6:
                state.warn(f"expression {name!r}: shape {shape_names[s]!r} is bound at {merged[s]:g} and "
                           f"{wt:g} on different meshes; one shape takes the larger")
            merged[s] = max(merged.get(s, 0.0), wt)
        names.append(name)
        presets.append(preset)
        bs.extend(merged)
        bw.extend(merged.values())
        offsets.append(len(bs))
        flags.append(flag)
    state.expressions = Expressions(tuple(names), tuple(presets), np.asarray(offsets, dtype=np.int64),
                                    np.asarray(bs, dtype=np.uint32), np.asarray(bw, dtype=np.float32),
                                    np.asarray(flags, dtype=np.int32).reshape(-1, 4))


class _TargetNames:
    """The morph target name of (mesh, target index) as the mesh reader names its shapes; each mesh's names and
    target count are worked out once (a VRM binds the same mesh many times)."""

    def __init__(self, state: ReadState) -> None:
        self.meshes = state.doc.get("meshes", [])
        self.of_mesh: dict[int, tuple[list, int, str]] = {}

    def __call__(self, mesh: int, index: int) -> str | None:
        if not (isinstance(mesh, int) and 0 <= mesh < len(self.meshes)) or not isinstance(index, int):
            return None
        if mesh not in self.of_mesh:
            m = self.meshes[mesh]
            names = target_names(m.get("extras"))
            prims = m.get("primitives") or [{}]
            if not names and isinstance(prims[0], dict):
                names = target_names(prims[0].get("extras"))
            n_targets = max((len(p.get("targets", [])) for p in prims if isinstance(p, dict)), default=0)
            base = m.get("name") if isinstance(m.get("name"), str) and m["name"] else f"mesh{mesh}"
            self.of_mesh[mesh] = (names, n_targets, base)
        names, n_targets, base = self.of_mesh[mesh]
        if not 0 <= index < n_targets:
            return None
        if index < len(names) and isinstance(names[index], str) and names[index]:
            return names[index]
        return f"{base}.{index}"


def _vrm0_expressions(state: ReadState, shape_index: dict, target_name: _TargetNames) -> list:
    f = state.f
    bsm = state.vrm0.get("blendShapeMaster", {})
    w = "extensions.VRM.blendShapeMaster.blendShapeGroups"
    groups = bsm.get("blendShapeGroups", []) if isinstance(bsm, dict) else None
    if not isinstance(groups, list):
        f.fail(w, "expected an array")

    def mesh_of(bind: dict, bw: str) -> tuple[int, str]:
        mesh = f.get(bind, "mesh", int, bw)
        return mesh, f"mesh {mesh}"

    rows = []
    for g, group in enumerate(groups):
        gw = f"{w}[{g}]"
        if not isinstance(group, dict):
            f.fail(gw, "expected an object")
        preset_name = f.get(group, "presetName", str, gw, "unknown").lower()
        preset = _VRM0_BY_LOWER.get(preset_name, "")
        name = preset or f.get(group, "name", str, gw, "") or f"expression{g}"
        shapes, weights = _binds(state, f.get(group, "binds", list, gw, []), f"{gw}.binds", mesh_of, 100.0,
                                 shape_index, target_name)
        binary = 1 if f.get(group, "isBinary", bool, gw, False) else 0
        rows.append((name, preset, shapes, weights, [binary, 0, 0, 0]))
    return rows


def _binds(state: ReadState, binds: list, where: str, mesh_of: Callable[[dict, str], tuple[int | None, str]],
           full: float, shape_index: dict, target_name: _TargetNames) -> tuple[list, list]:
    """(shapes, weights in 0..1) of a VRM expression's morph-target binds (``full``: the weight of 100 %);
    a bind naming no morph target of the scene is dropped with a warning."""
    f = state.f
    shapes, weights = [], []
    for b, bind in enumerate(binds):
        bw = f"{where}[{b}]"
        if not isinstance(bind, dict):
            f.fail(bw, "expected an object")
        mesh, label = mesh_of(bind, bw)
        index = f.get(bind, "index", int, bw)
        weight = f.get(bind, "weight", float, bw, full)
        tname = target_name(mesh, index)
        if tname is None or tname not in shape_index:
            state.warn(f"{bw}: {label} target {index} is not a morph target in the scene (dropped)")
            continue
        shapes.append(shape_index[tname])
        weights.append(float(np.clip(weight / full, 0.0, 1.0)))
    return shapes, weights


def _vrm1_expressions(state: ReadState, shape_index: dict, target_name: _TargetNames) -> list:
    f = state.f

    def node_mesh(bind: dict, bw: str) -> tuple[int | None, str]:
        node = f.get(bind, "node", int, bw)
        return f.obj("nodes", node, f"{bw}.node").get("mesh"), f"node {node}"

    ex = state.vrm1.get("expressions", {})
    w = "extensions.VRMC_vrm.expressions"
    if not isinstance(ex, dict):
        f.fail(w, "expected an object")
    rows = []
    for group in ("preset", "custom"):
        table = ex.get(group, {})
        if not isinstance(table, dict):
            f.fail(f"{w}.{group}", "expected an object of name -> expression")
        for key, e in table.items():
            ew = f"{w}.{group}.{key}"
            if not isinstance(e, dict):
                f.fail(ew, "expected an object")
            preset = _VRM0_FROM_VRM1.get(key, "") if group == "preset" else ""
            name = preset or key
            shapes, weights = _binds(state, f.get(e, "morphTargetBinds", list, ew, []), f"{ew}.morphTargetBinds",
                                     node_mesh, 1.0, shape_index, target_name)
            flag = [1 if f.get(e, "isBinary", bool, ew, False) else 0]
            for k in ("overrideBlink", "overrideLookAt", "overrideMouth"):
                v = f.get(e, k, str, ew, "none")
                if v not in OVERRIDES:
                    f.fail(f"{ew}.{k}", f"{v!r} is not none, block or blend")
                flag.append(OVERRIDES[v])
            rows.append((name, preset, shapes, weights, flag))
    return rows


def expression_rows(w: WriteState) -> list[tuple[str, str, list[tuple[int, float]], np.ndarray]]:
    """(name, VRM 0.x preset or "", [(shape, weight)], flags) for each expression to write: the character's own,
    then one for each shape with an ARKit name that no expression has yet (perfect sync)."""
    c = w.c
    rows = []
    have: set[str] = set()
    if c.expressions is not None:
        e = c.expressions
        for i, name in enumerate(e.names):
            s, wt = e.binds(i)
            rows.append((name, e.presets[i], list(zip(s.tolist(), wt.tolist())), e.flags[i]))
            have.add(name)
            have.add(canonical(name))
    for s, name in enumerate(c.shape_names):
        key = canonical(name)
        if key in _ARKIT and pascal(name) not in have and key not in have:
            rows.append((pascal(name), "", [(s, 1.0)], np.zeros(4, np.int32)))
            have.update((pascal(name), key))
            w.summary.added_expressions.append(pascal(name))
    w.summary.n_expressions = len(rows)
    return rows


def _mesh_binds(w: WriteState, binds: list[tuple[int, float]]) -> list[tuple[int, int, float]]:
    """(mesh, target index, weight) of each bind: a shape on several meshes binds on each."""
    out = []
    for s, wt in binds:
        for m, index in enumerate(w.target_index):
            if s in index:
                out.append((m, index[s], float(wt)))
    return out


def write_expressions0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``blendShapeMaster.blendShapeGroups``: binds {mesh, index, weight 0..100}, isBinary."""
    groups = []
    on_materials = material_binds(w)
    for name, preset, binds, flags in expression_rows(w):
        groups.append({"name": name, "presetName": preset.lower() if preset else "unknown",
                       "binds": [{"mesh": m, "index": k, "weight": float(np.clip(wt, 0, 1) * 100.0)}
                                 for m, k, wt in _mesh_binds(w, binds)],
                       "materialValues": write_binds0(w, name, on_materials.get(name)), "isBinary": bool(flags[0])})
    vrm["blendShapeMaster"] = {"blendShapeGroups": groups}


def write_expressions1(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 1.0 ``expressions``: preset (by the 1.0 preset name) and custom, binds {node, index, weight 0..1},
    isBinary and the three overrides."""
    preset, custom = {}, {}
    on_materials = material_binds(w)
    for name, p, binds, flags in expression_rows(w):
        e: dict[str, Any] = {"morphTargetBinds": [{"node": w.host[m], "index": k, "weight": float(np.clip(wt, 0, 1))}
                                                  for m, k, wt in _mesh_binds(w, binds)],
                             **write_binds1(on_materials.get(name)), "isBinary": bool(flags[0])}
        for col, key in ((1, "overrideBlink"), (2, "overrideLookAt"), (3, "overrideMouth")):
            e[key] = _OVERRIDE_NAME.get(int(flags[col]), "none")
        key = VRM1_FROM_VRM0.get(p, "") if p else (name if name in _VRM1_PRESETS else "")
        (preset if key else custom)[key or name] = e
    vrm["expressions"] = {"preset": preset, "custom": custom}
