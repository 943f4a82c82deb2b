"""Rig import: a tiny hand-made rig checked exactly, error messages, the CLI, and the real ICT head."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.model.geometry import vertex_normals

from conftest import need_shared
from facepuppet.offline.io.obj import ObjError
from facepuppet.offline.io.rig_import import (
    IRIS,
    KIND_COLOR,
    NORMAL_TOLERANCE,
    PUPIL,
    SCLERA,
    import_rig,
    material_kind,
)

# 4 x 4 grid in the x-y plane facing +z: 3 x 3 quads, the top two rows skin, the bottom row teeth
GRID = np.array([[x, y, 0.0] for y in range(4) for x in range(4)])
QUADS = [(r * 4 + c + 1, r * 4 + c + 2, r * 4 + c + 6, r * 4 + c + 5) for r in range(3) for c in range(3)]


def obj_text(vertices):
    lines = ["mtllib rig.mtl"] + [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += ["usemtl M_Teeth"] + [f"f {a} {b} {c} {d}" for a, b, c, d in QUADS[:3]]
    lines += ["usemtl M_Face"] + [f"f {a} {b} {c} {d}" for a, b, c, d in QUADS[3:]]
    return "\n".join(lines) + "\n"


@pytest.fixture
def rig(tmp_path):
    """neutral.obj + rig.mtl + shapes/jawOpen.obj (moves vertex 5 out of plane) + shapes/eyeBlink_L.obj."""
    (tmp_path / "neutral.obj").write_text(obj_text(GRID))
    (tmp_path / "rig.mtl").write_text("newmtl M_Face\nKs 0.1 0.1 0.1\nNs 20\nnewmtl M_Teeth\nKs 0.5 0.5 0.5\nNs 40\n")
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    jaw = GRID.copy()
    jaw[5] += (0.1, 0.0, 0.5)
    blink = GRID.copy()
    blink[0, 2] += 1e-7  # below the tolerance, and its normal barely turns: not stored
    blink[15] += (0.25, 0.0, 0.0)  # in the plane: moves, but no normal changes
    (shapes / "jawOpen.obj").write_text(obj_text(jaw))
    (shapes / "eyeBlink_L.obj").write_text(obj_text(blink))
    return tmp_path, {"jawOpen": jaw, "eyeBlink_L": blink}


def test_tiny_rig_deltas_are_exact_and_sparse(rig):
    root, shapes = rig
    ch = import_rig(root / "neutral.obj", root / "shapes")
    assert ch.shape_names == ("eyeBlink_L", "jawOpen")  # sorted file stems, spelling kept
    assert len(ch.triangles) == 18 and ch.material_names == ("M_Teeth", "M_Face")
    np.testing.assert_array_equal(ch.triangle_material, [0] * 6 + [1] * 12)
    np.testing.assert_array_equal(ch.vertices, GRID.astype(np.float32))
    tris = ch.triangles.astype(np.int64)
    dense = ch.dense_deltas()
    dense_n = ch.dense_deltas(normals=True)
    for s, name in enumerate(ch.shape_names):
        exact = shapes[name] - GRID
        d_normal = vertex_normals(shapes[name], tris).astype(np.float64) - vertex_normals(GRID, tris)
        stored = ch.delta_indices[ch.shape_slice(s)]
        expected = np.flatnonzero(
            (np.linalg.norm(exact, axis=1) > 1e-5) | (np.linalg.norm(d_normal, axis=1) > NORMAL_TOLERANCE)
        )
        np.testing.assert_array_equal(stored, expected)
        np.testing.assert_array_equal(dense[s][stored], exact[stored].astype(np.float32))
        np.testing.assert_allclose(dense_n[s][stored], d_normal[stored], atol=1e-6)
    blink = ch.delta_indices[ch.shape_slice(0)]
    np.testing.assert_array_equal(blink, [15])
    jaw = ch.delta_indices[ch.shape_slice(1)]
    assert {0, 4, 5} <= set(jaw.tolist()) and not {2, 15} & set(jaw.tolist())  # triangles around 5 turn
    metrics = ch.metadata["metrics"]["shapes"]
    assert metrics["jawOpen"]["moved"] == 1 and metrics["jawOpen"]["stored"] == len(jaw)
    assert metrics["jawOpen"]["max_displacement"] == pytest.approx(np.hypot(0.1, 0.5))
    assert metrics["eyeBlink_L"] == {"moved": 1, "stored": 1, "max_displacement": pytest.approx(0.25)}


def test_tiny_rig_materials_colours_and_round_trip(rig, tmp_path):
    root, _ = rig
    ch = import_rig(root / "neutral.obj", root / "shapes", name="tiny", pivot=(1, 2, 3))
    np.testing.assert_allclose(ch.material_params, [[0.5, 40, MATERIAL_KINDS["teeth"], 0], [0.1, 20, 0, 0]])
    np.testing.assert_allclose(ch.vertex_color[0], KIND_COLOR["teeth"], atol=1e-6)  # first material wins
    np.testing.assert_allclose(ch.vertex_color[15], KIND_COLOR["skin"], atol=1e-6)
    out = ch.save(tmp_path / "tiny.npz")
    back = Character.load(out)
    assert back.name == "tiny" and back.units == "cm" and back.shape_names == ch.shape_names
    for field in ("vertices", "triangles", "triangle_material", "vertex_color", "material_params", "pivot",
                  "delta_offsets", "delta_indices", "delta_positions", "delta_normals"):  # fmt: skip
        np.testing.assert_array_equal(getattr(back, field), getattr(ch, field), err_msg=field)
    np.testing.assert_array_equal(back.pivot, [1, 2, 3])
    assert back.metadata["input_hash"] == ch.metadata["input_hash"]
    assert back.metadata["input_hash"].startswith("sha256:")


def test_explicit_shapes_and_neutral_inside_the_folder_is_skipped(rig):
    root, _ = rig
    (root / "shapes" / "neutral.obj").write_text(obj_text(GRID))
    ch = import_rig(root / "shapes" / "neutral.obj", root / "shapes")
    assert ch.shape_names == ("eyeBlink_L", "jawOpen")
    ch = import_rig(root / "neutral.obj", root / "shapes", shapes=["jawOpen"])
    assert ch.shape_names == ("jawOpen",)


@pytest.mark.parametrize(
    "name, kind",
    [("M_Face", "skin"), ("M_EyeBlend", "film"), ("M_EyeOcclusion", "occlusion"), ("M_LacrimalFluid", "film"),
     ("Cornea_L", "hidden"),
     ("M_ScleraLeft", "eye"), ("M_IrisRight", "eye"), ("Eyeball", "eye"), ("M_Teeth", "teeth"),
     ("M_GumsTongue", "mouth"), ("M_EyeLashes", "lashes"), ("Lips", "lips")],
)  # fmt: skip
def test_material_kinds_from_names(name, kind):
    assert material_kind(name) == kind


def test_mismatched_vertex_count_names_both_files_and_counts(rig):
    root, _ = rig
    (root / "shapes" / "mouthClose.obj").write_text(obj_text(GRID[:-1]).replace("f 11 12 16 15\n", ""))
    with pytest.raises(ValueError, match=r"mouthClose\.obj: has 15 vertices but the neutral .*neutral\.obj has 16"):
        import_rig(root / "neutral.obj", root / "shapes")


def test_nan_coordinate_names_file_and_line(rig):
    root, _ = rig
    text = obj_text(GRID).splitlines()
    text[4] = "v 3 nan 0"
    (root / "shapes" / "mouthClose.obj").write_text("\n".join(text) + "\n")
    with pytest.raises(ObjError, match=r"mouthClose\.obj:5: non-finite number in 'v 3 nan 0'"):
        import_rig(root / "neutral.obj", root / "shapes")


def test_missing_inputs_and_garbled_neutral(rig, tmp_path):
    root, _ = rig
    with pytest.raises(FileNotFoundError, match=r"nope\.obj: neutral OBJ not found"):
        import_rig(root / "nope.obj", root / "shapes")
    with pytest.raises(FileNotFoundError, match=r"nodir: shapes folder not found"):
        import_rig(root / "neutral.obj", root / "nodir")
    (root / "empty").mkdir()
    with pytest.raises(ValueError, match=r"empty: no shape OBJ files"):
        import_rig(root / "neutral.obj", root / "empty")
    with pytest.raises(FileNotFoundError, match=r"browDown_L\.obj: shape OBJ not found"):
        import_rig(root / "neutral.obj", root / "shapes", shapes=["browDown_L"])
    (root / "neutral.obj").write_text(obj_text(GRID).replace("f 1 2 6 5", "f 1 2 6/ /5"))
    with pytest.raises(ObjError, match=r"neutral\.obj:19: bad face corner '/5'"):
        import_rig(root / "neutral.obj", root / "shapes")


def test_landmark_file_is_checked(rig):
    root, _ = rig
    (root / "marks.json").write_text(json.dumps({"idx_to_landmark_verts": [0] * 67 + [99]}))
    with pytest.raises(ValueError, match=r"marks\.json: idx_to_landmark_verts: expected 68 indices in 0\.\.15"):
        import_rig(root / "neutral.obj", root / "shapes", landmarks=root / "marks.json")


def test_cli_import_rig(rig, tmp_path, capsys):
    root, _ = rig
    out = tmp_path / "cli.npz"
    code = main(["import-rig", str(root / "neutral.obj"), str(root / "shapes"), "-o", str(out), "--name", "cli"])
    assert code == 0
    captured = capsys.readouterr()
    assert "stored deltas" in captured.out
    assert "import-rig:" not in captured.err    # progress only on a terminal (tests/offline/test_command_progress.py)
    ch = Character.load(out)
    assert ch.name == "cli" and ch.n_shapes == 2
    code = main(["import-rig", str(root / "none.obj"), str(root / "shapes"), "-o", str(tmp_path / "new.npz")])
    assert code == 2 and "none.obj: neutral OBJ not found" in capsys.readouterr().err


# -- the real ICT-FaceKit head -------------------------------------------------


def raw_vertices(path):
    """The obvious reader: every 'v' line, one at a time."""
    rows = []
    with open(path) as handle:
        for line in handle:
            if line.startswith("v "):
                rows.append([float(x) for x in line.split()[1:4]])
    return np.array(rows)


def test_ict_head_shapes_and_deltas(ict_character):
    ict = need_shared("ict-facekit")
    ch = ict_character
    assert ch.n_vertices == 26719 and ch.units == "cm"
    assert ch.n_shapes >= 50 and {"jawOpen", "eyeBlink_L", "mouthSmile_R"} <= set(ch.shape_names)
    s = ch.shape_names.index("jawOpen")
    exact = raw_vertices(ict / "jawOpen.obj") - raw_vertices(ict / "generic_neutral_mesh.obj")
    dense = ch.dense_deltas()[s]
    stored = ch.delta_indices[ch.shape_slice(s)]
    sample = np.random.default_rng(7).choice(stored, 300, replace=False)
    np.testing.assert_allclose(dense[sample], exact[sample], rtol=1e-6, atol=1e-6)
    dropped = np.setdiff1d(np.arange(ch.n_vertices), stored)
    assert np.linalg.norm(exact[dropped], axis=1).max() <= 1e-5
    assert np.abs(exact[stored]).max() == pytest.approx(np.abs(dense).max(), rel=1e-6)
    assert len(ch.delta_indices) < 0.6 * ch.n_shapes * ch.n_vertices


def test_ict_materials_and_colours(ict_character):
    ch = ict_character
    kinds = {m: int(p[2]) for m, p in zip(ch.material_names, ch.material_params)}
    # the eye's thin layers are drawn blended (issue 13): occlusion and films, not hidden
    assert kinds["M_EyeOcclusion"] == MATERIAL_KINDS["occlusion"]
    assert kinds["M_EyeBlend"] == kinds["M_LacrimalFluid"] == MATERIAL_KINDS["film"]
    assert kinds["M_Teeth"] == MATERIAL_KINDS["teeth"] and kinds["M_IrisLeft"] == MATERIAL_KINDS["eye"]
    assert kinds["M_Face"] == MATERIAL_KINDS["skin"] and kinds["M_GumsTongue"] == MATERIAL_KINDS["mouth"]
    lip = np.all(np.abs(ch.vertex_color - KIND_COLOR["lips"]) < 1e-3, axis=1)
    assert 200 < lip.sum() < 3000  # the lips, not the whole face
    lip_y = ch.vertices[lip, 1]
    assert -5.0 < lip_y.min() and lip_y.max() < -2.0  # between the mouth landmarks' heights, cm
    eye_kind = ch.material_params[ch.triangle_material, 2] == MATERIAL_KINDS["eye"]
    eye_vertices = np.unique(ch.triangles[eye_kind])
    for rgb in (SCLERA, IRIS, PUPIL):
        share = np.mean(np.all(np.abs(ch.vertex_color[eye_vertices] - rgb) < 1e-6, axis=1))
        assert 0.01 < share < 0.9, rgb


def test_a_coordinate_beyond_float32_names_file_and_line(rig):
    root, _ = rig
    text = obj_text(GRID).splitlines()
    text[3] = "v 1e39 0 0"
    (root / "neutral.obj").write_text("\n".join(text) + "\n")
    with pytest.raises(ObjError, match=r"neutral\.obj:4: coordinate beyond the float32 range in 'v 1e39 0 0'"):
        import_rig(root / "neutral.obj", root / "shapes")


def test_a_neutral_without_faces_is_refused_naming_it(rig):
    root, _ = rig
    text = [line for line in obj_text(GRID).splitlines() if not line.startswith("f ")]
    (root / "neutral.obj").write_text("\n".join(text) + "\n")
    for shape in ("jawOpen", "eyeBlink_L"):
        (root / "shapes" / f"{shape}.obj").write_text("\n".join(text) + "\n")
    with pytest.raises(ObjError, match=r"neutral\.obj: no faces \('f' lines\)"):
        import_rig(root / "neutral.obj", root / "shapes")


def test_a_shape_moving_a_vertex_beyond_float32_is_refused_naming_the_shape(rig):
    """Each file is within float32, but the shape's delta (-6e38) is not (it was '<tables>: delta_positions')."""
    import warnings

    root, _ = rig
    near_max = GRID.copy()
    near_max[5] = (3e38, 0, 0)
    (root / "neutral.obj").write_text(obj_text(near_max))
    near_max[5] = (-3e38, 0, 0)
    (root / "shapes" / "jawOpen.obj").write_text(obj_text(near_max))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(ObjError, match=r"jawOpen\.obj: moves vertex 5 by \[-6e\+38, 0\.0, 0\.0\], beyond the "
                                           r"float32 range"):
            import_rig(root / "neutral.obj", root / "shapes")


@pytest.mark.parametrize("forward, turn", [("-z", lambda p: p * (-1, 1, -1)),
                                           ("+x", lambda p: p[:, [2, 1, 0]] * (1, 1, -1)),
                                           ("-x", lambda p: p[:, [2, 1, 0]] * (-1, 1, 1))])
def test_a_rig_facing_another_axis_is_turned_to_face_plus_z(rig, tmp_path_factory, forward, turn):
    """The same rig written facing -Z / +X / -X and imported with ``forward`` is the +Z import (shapes too)."""
    root, shapes = rig
    want = import_rig(root / "neutral.obj", root / "shapes")
    other = tmp_path_factory.mktemp("turned")
    (other / "neutral.obj").write_text(obj_text(turn(GRID)))
    (other / "rig.mtl").write_text((root / "rig.mtl").read_text())
    (other / "shapes").mkdir()
    for name, verts in shapes.items():
        (other / "shapes" / f"{name}.obj").write_text(obj_text(turn(verts)))
    # the turned grid faces the other way: its quads wind the same, so its normals point along ``forward``
    got = import_rig(other / "neutral.obj", other / "shapes", forward=forward)
    np.testing.assert_allclose(got.vertices, want.vertices, atol=1e-6)
    np.testing.assert_allclose(got.dense_deltas(), want.dense_deltas(), atol=1e-6)
    np.testing.assert_allclose(got.rest_normals(), want.rest_normals(), atol=1e-6)
    np.testing.assert_allclose(got.pivot, want.pivot, atol=1e-6)
    assert got.metadata["settings"]["forward"] == forward


def test_an_unknown_forward_is_refused(rig):
    root, _ = rig
    with pytest.raises(ValueError, match="forward: expected one of"):
        import_rig(root / "neutral.obj", None, forward="up")


def test_a_fifo_as_the_neutral_is_refused_without_being_opened(tmp_path, capsys):
    fifo = tmp_path / "neutral.obj"
    os.mkfifo(fifo)  # opening it would block until a writer came: it must never be opened
    code = main(["import-rig", str(fifo), "-o", str(tmp_path / "c.npz")])
    assert code == 2 and f"{fifo}: expected a neutral OBJ, found a FIFO (named pipe)" in capsys.readouterr().err
    assert not (tmp_path / "c.npz").exists()
