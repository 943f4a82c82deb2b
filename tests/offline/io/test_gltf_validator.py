"""Exports checked by the Khronos glTF-Validator (the reference for a valid glTF 2.0 file).

Every data-kit file exported to each format it can take, and the characters the tests build, must give
0 errors and no warning code the original file did not have. One warning is inherent to a format, not to
the export: VRM 0.x's extension is named ``VRM``, without the vendor prefix and underscore glTF asks
(``INVALID_EXTENSION_NAME_FORMAT`` at ``/extensionsUsed``); every VRM 0.x file has it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from helpers.gltf_characters import SHEARED, parts_character
from helpers.gltf_validator import ERROR, WARNING, codes, need_validator, problems, validate

KIT_VRM = ["Godette_vrm_v4.vrm", "VRMC_materials_mtoon_UV_Animation_Test.vrm",
           "VRMC_vrm_expressions_isBinary_Overrides.vrm", "modifier_shapekey_vrm0.vrm",
           "pose_rotation_scale_shape_key_skinned.vrm", "simple_morph.vrm", "subdivision_shapekey_modifier_vrm1.vrm"]
KIT_GLTF = ["SimpleMorph.gltf"]
SUFFIX = {"glb": ".glb", "gltf": ".gltf", "vrm0": ".vrm", "vrm1": ".vrm"}
#: Warnings every file of a format has, whatever wrote it (see the module doc).
FORMAT_WARNINGS = {"vrm0": {"INVALID_EXTENSION_NAME_FORMAT"}}


def export(c, tmp_path: Path, fmt: str, stem: str = "out") -> Path:
    out = tmp_path / f"{stem}_{fmt}{SUFFIX[fmt]}"
    export_character(c, out, vrm=int(fmt[3]) if fmt.startswith("vrm") else None)
    return out


def check_against(original: dict, exported: dict, fmt: str) -> None:
    """0 errors, and only warning codes the original had (or its format always has)."""
    assert exported["numErrors"] == 0, problems(exported, ERROR)
    allowed = set(codes(original, WARNING)) | FORMAT_WARNINGS.get(fmt, set())
    new = [p for p in problems(exported, WARNING) if p.split(" ", 1)[0] not in allowed]
    assert not new, f"warnings the original did not have: {new}"


@pytest.mark.data
@pytest.mark.slow
@pytest.mark.parametrize("name", KIT_VRM + KIT_GLTF)
def test_every_kit_file_exports_valid_in_every_format(tmp_path, name):
    need_validator()
    path = need_shared("gltf", name)
    c = read_gltf(path)
    fmts = ["vrm0", "vrm1", "glb"] if name in KIT_VRM else ["glb", "gltf"]
    outs = [export(c, tmp_path, fmt) for fmt in fmts]
    original, *exported = validate(path, *outs)
    assert original["numErrors"] == 0
    for fmt, report in zip(fmts, exported):
        check_against(original, report, fmt)


@pytest.mark.parametrize("fmt", ["glb", "gltf", "vrm0", "vrm1"])
@pytest.mark.parametrize("mesh_nodes", [False, True])
def test_the_test_characters_export_valid(tmp_path, fmt, mesh_nodes):
    """The built character's one deliberate problem: its ``hat`` node has a sheared rest matrix, which glTF
    cannot say as TRS; the writer keeps it as a ``matrix`` (the exact rest pose), which the validator calls
    NODE_MATRIX_NON_TRS. Nothing else may be reported."""
    need_validator()
    c = parts_character(mesh_nodes=mesh_nodes)
    hat = c.skeleton.names.index(SHEARED)
    (report,) = validate(export(c, tmp_path, fmt))
    errors = [m for m in report["messages"] if m["severity"] == ERROR]
    assert [(m["code"], m["pointer"]) for m in errors] == [("NODE_MATRIX_NON_TRS", f"/nodes/{hat}/matrix")]
    assert set(codes(report, WARNING)) <= FORMAT_WARNINGS.get(fmt, set()), problems(report, WARNING)
