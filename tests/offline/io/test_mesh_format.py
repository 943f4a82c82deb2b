"""import-rig names the format of a mesh file that is not an OBJ, and what it accepts."""

from __future__ import annotations

import shutil

import pytest

from conftest import need_shared
from facepuppet.offline.io.mesh_format import sniff_mesh_format
from facepuppet.offline.io.rig_import import import_rig


def _obj(path, dz=0.0):
    path.write_text(f"v 0 0 {dz}\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return path


@pytest.mark.data
@pytest.mark.parametrize("asset, found", [("gltf/simple_morph.vrm", "glTF binary"),
                                          ("gltf/SimpleMorph.gltf", "glTF JSON")])
def test_a_gltf_neutral_is_refused_naming_its_format_and_the_accepted_one(tmp_path, asset, found):
    neutral = tmp_path / "head.glb"
    shutil.copyfile(need_shared(*asset.split("/")), neutral)
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    _obj(shapes / "jawOpen.obj", 0.1)
    with pytest.raises(ValueError, match=rf"head.glb: the neutral is a {found}.* file, not an OBJ; "
                                         r"import-rig reads Wavefront OBJ") as info:
        import_rig(neutral, shapes)
    assert "no vertices" not in str(info.value)


@pytest.mark.parametrize("head, found", [(b"Kaydara FBX Binary  \x00\x1a\x00", "FBX (binary)"),
                                         (b"; FBX 7.4.0 project file\n", "FBX (ASCII)"),
                                         (b"ply\nformat ascii 1.0\n", "PLY"),
                                         (b"solid head\n facet normal 0 0 1\n", "STL (ASCII)"),
                                         (b'<?xml version="1.0"?>\n<COLLADA>', "Collada (.dae)")])
def test_other_mesh_formats_are_named(tmp_path, head, found):
    path = tmp_path / "x.obj"
    path.write_bytes(head + b"\x00" * 64)
    assert sniff_mesh_format(path) == found
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    _obj(shapes / "a.obj")
    with pytest.raises(ValueError, match=rf"x.obj: the neutral is a {found.replace('(', '.').replace(')', '.')} file"):
        import_rig(path, shapes)
    neutral = _obj(tmp_path / "neutral.obj")                     # a shape in another format: named too
    (shapes / "b.obj").write_bytes(head)
    with pytest.raises(ValueError, match=r"b.obj: a shape is a .* file, not an OBJ"):
        import_rig(neutral, shapes)


def test_an_obj_is_not_mistaken_for_another_format(tmp_path):
    assert sniff_mesh_format(_obj(tmp_path / "a.obj")) is None
