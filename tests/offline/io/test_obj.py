"""OBJ reader: small hand-written files, error messages, and the ICT neutral against an obvious parser."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import need_shared
from facepuppet.offline.io.mtl import read_mtl
from facepuppet.offline.io.obj import ObjError, read_obj, read_vertices_only

SMALL = """# a comment
mtllib mats.mtl
o thing
v 0 0 0
v 1 0 0
v 1 1 0
  v 0 1 0   # leading blank and trailing comment
v 2 0 0 1.0
v 2 1 0
v 3 0.5 0
vt 0 0
vt 1 0
vt 1 1
vn 0 0 1
g top
usemtl skin
s 1
f 1/1/1 2/2/1 3/3/1 4/1/1
f 2//1 5//1 6//1

usemtl teeth
f -5 -3 -1 -2 -4
usemtl skin
f 1/2 2/3 4/1
"""


def write(tmp_path, text, name="m.obj", newline="\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def reference_triangles(text):
    """Slow obvious reader: per line, fan-triangulate with 1-based / negative indices."""
    tris, mats, n_v, current, names = [], [], 0, None, []
    for line in text.splitlines():
        parts = line.split("#")[0].split()
        if not parts:
            continue
        if parts[0] == "v":
            n_v += 1
        elif parts[0] == "usemtl":
            current = parts[1]
            if current not in names:
                names.append(current)
        elif parts[0] == "f":
            idx = [int(c.split("/")[0]) for c in parts[1:]]
            idx = [i - 1 if i > 0 else n_v + i for i in idx]
            for j in range(1, len(idx) - 1):
                tris.append([idx[0], idx[j], idx[j + 1]])
                mats.append(names.index(current))
    return np.array(tris), np.array(mats), tuple(names)


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_small_file_triangulates_polygons_and_keeps_materials(tmp_path, newline):
    mesh = read_obj(write(tmp_path, SMALL, newline=newline))
    assert mesh.vertices.shape == (7, 3) and mesh.vertices.dtype == np.float64
    np.testing.assert_array_equal(mesh.vertices[3], [0, 1, 0])
    np.testing.assert_array_equal(mesh.vertices[4], [2, 0, 0])  # w dropped
    # quad -> 2, triangle -> 1, pentagon -> 3, triangle -> 1
    assert mesh.n_faces == 4 and len(mesh.triangles) == 7
    np.testing.assert_array_equal(mesh.triangles[:2], [[0, 1, 2], [0, 2, 3]])
    # the pentagon "f -5 -3 -1 -2 -4" with 7 vertices defined before it
    np.testing.assert_array_equal(mesh.triangles[3:6], [[2, 4, 6], [2, 6, 5], [2, 5, 3]])
    assert mesh.material_names == ("skin", "teeth")
    np.testing.assert_array_equal(mesh.triangle_material, [0, 0, 0, 1, 1, 1, 0])
    tris, mats, names = reference_triangles(SMALL)
    np.testing.assert_array_equal(mesh.triangles, tris)
    np.testing.assert_array_equal(mesh.triangle_material, mats)
    assert mesh.mtllib == "mats.mtl"
    assert mesh.texcoords.shape == (3, 2) and mesh.normals.shape == (1, 3)
    assert mesh.vertex_colors is None


def test_faces_before_usemtl_get_default_material_and_vertex_colours_are_kept(tmp_path):
    path = write(tmp_path, "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nv 1 1 0\nf 1 2 3\nusemtl a\nf 2 4 3\n")
    mesh = read_obj(path)
    assert mesh.material_names == ("default", "a")
    np.testing.assert_array_equal(mesh.triangle_material, [0, 1])
    np.testing.assert_array_equal(mesh.vertex_colors, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    assert mesh.mtllib is None


@pytest.mark.parametrize(
    "text, match",
    [
        ("v 0 0 0\nv 1 0 zero\n", r"m\.obj:2: not a number: 'zero'"),
        ("v 0 0 0\nv 1 0\n", r"m\.obj:2: 'v' needs 3 or 4 or 6 or 7 numbers, got 2"),
        ("v 0 0 0\n\nv nan 0 0\n", r"m\.obj:3: non-finite number in 'v nan 0 0'"),
        ("v 0 0 0\nv 1 0 0\nv 0 inf 0\n", r"m\.obj:3: non-finite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"m\.obj:4: a face needs at least 3 corners, got 2"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x/1\n", r"m\.obj:4: bad face corner 'x/1'"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", r"m\.obj:4: bad face corner '0'"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"m\.obj:4: vertex index 4 out of range for 3 vertices"),
        ("v 0 0 0\nv 1 0 0\nf 1 2 -3\nv 0 1 0\n", r"m\.obj:3: vertex index -3 out of range for 2 vertices"),
        ("# nothing\nvt 0 0\n", r"m\.obj: no vertices"),
    ],
)
def test_errors_name_file_and_line(tmp_path, text, match):
    with pytest.raises(ObjError, match=match):
        read_obj(write(tmp_path, text))


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.obj: OBJ file not found"):
        read_obj(tmp_path / "nope.obj")


def test_read_vertices_only_checks_count_and_numbers(tmp_path):
    path = write(tmp_path, SMALL)
    np.testing.assert_array_equal(read_vertices_only(path), read_obj(path).vertices)
    with pytest.raises(ObjError, match=r"m\.obj: has 7 vertices, expected 8"):
        read_vertices_only(path, expected=8)
    bad = write(tmp_path, "v 0 0 0\nf 1 1 1\nv 0 NaN 0\n", name="bad.obj")
    with pytest.raises(ObjError, match=r"bad\.obj:3: non-finite"):
        read_vertices_only(bad)


def test_mtl_reads_kd_ks_ns(tmp_path):
    path = tmp_path / "mats.mtl"
    path.write_text("newmtl skin\nKd 0.8 0.5 0.4\nKs 0.1\nNs 20\nillum 2\n\nnewmtl teeth\nKs 0.7 0.6 0.5\n")
    mats = read_mtl(path)
    assert list(mats) == ["skin", "teeth"]
    assert mats["skin"].diffuse == (0.8, 0.5, 0.4) and mats["skin"].specular == (0.1, 0.1, 0.1)
    assert mats["skin"].shininess == 20 and mats["teeth"].specular == (0.7, 0.6, 0.5)
    path.write_text("newmtl a\nKd 0.8 x 0.4\n")
    with pytest.raises(ObjError, match=r"mats\.mtl:2: expected finite numbers"):
        read_mtl(path)


@pytest.mark.data
def test_ict_neutral_matches_an_obvious_reader():
    path = need_shared("ict-facekit", "generic_neutral_mesh.obj")
    mesh = read_obj(path)
    text = path.read_text()
    vertices = np.array([[float(x) for x in ln.split()[1:4]] for ln in text.splitlines() if ln.startswith("v ")])
    tris, mats, names = reference_triangles(text)
    assert mesh.vertices.shape == (26719, 3)
    np.testing.assert_array_equal(mesh.vertices, vertices)
    np.testing.assert_array_equal(mesh.triangles, tris)
    np.testing.assert_array_equal(mesh.triangle_material, mats)
    assert mesh.material_names == names and len(names) == 12
    assert mesh.n_faces == 26384 and len(mesh.triangles) == 25836 * 2 + 548
