"""The tables contract: round trip, and refusal of every kind of bad file."""

from __future__ import annotations

import io
import json
import pickle
import zipfile

import numpy as np
import pytest

from facepuppet.runtime.character import Character, sparse_deltas
from facepuppet.runtime.tables import (
    SCHEMA_VERSION,
    TablesError,
    hash_inputs,
    load_tables,
    save_tables,
)


def tiny_character() -> Character:
    """A unit quad (two triangles) with two shapes, built by hand."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    dense = np.zeros((2, 4, 3), dtype=np.float32)
    dense[0, 2] = [0, 0.5, 0]  # jawOpen moves one corner
    dense[1, 0] = [0.1, 0, 0.2]  # eyeBlinkLeft moves another
    offsets, indices, values = sparse_deltas(dense)
    return Character(
        name="quad",
        units="cm",
        vertices=vertices,
        triangles=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
        triangle_material=np.array([0, 1], dtype=np.uint16),
        vertex_color=np.full((4, 3), 0.5, dtype=np.float32),
        material_names=("M_Face", "M_Teeth"),
        material_params=np.array([[0.1, 16, 0, 0], [0.3, 32, 2, 0]], dtype=np.float32),
        pivot=np.zeros(3, dtype=np.float32),
        shape_names=("jawOpen", "eyeBlinkLeft"),
        delta_offsets=offsets,
        delta_indices=indices,
        delta_positions=values,
        delta_normals=np.zeros_like(values),
        metadata={"metrics": {"max_delta": 0.5}, "input_hash": hash_inputs(b"quad")},
    )


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / "quad.npz"
    tiny_character().save(path)
    return path


def rewrite(src, dst, *, manifest=None, arrays=None, drop=(), extra=None):
    """Copy a tables archive, replacing the manifest or arrays (a forger's tool for the tests)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.namelist():
            key = item[:-4]
            if key in drop:
                continue
            data = zin.read(item)
            if key == "__manifest__" and manifest is not None:
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.frombuffer(json.dumps(manifest).encode(), np.uint8))
                data = buf.getvalue()
            elif arrays and key in arrays:
                buf = io.BytesIO()
                np.lib.format.write_array(buf, arrays[key], allow_pickle=True)
                data = buf.getvalue()
            zout.writestr(item, data)
        for key, arr in (extra or {}).items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, arr, allow_pickle=True)
            zout.writestr(key + ".npy", buf.getvalue())
    return dst


def manifest_of(path) -> dict:
    return load_tables(path).manifest.copy()


def test_round_trip_keeps_every_array_and_the_manifest(saved):
    original = tiny_character()
    loaded = Character.load(saved)
    for name, arr in original._arrays().items():
        got = getattr(loaded, name)
        assert got.dtype == arr.dtype, name
        np.testing.assert_array_equal(got, arr, err_msg=name)
    assert loaded.shape_names == original.shape_names
    assert loaded.material_names == original.material_names
    assert loaded.units == "cm" and loaded.name == "quad"
    manifest = load_tables(saved).manifest
    assert manifest["schema_version"] == SCHEMA_VERSION
    assert manifest["kind"] == "character"
    assert manifest["sections"]["vertices"] == {
        "shape": [4, 3], "dtype": "float32", "kind": "neutral vertex positions"
    }
    assert manifest["metrics"] == {"max_delta": 0.5}
    assert manifest["input_hash"].startswith("sha256:")
    np.testing.assert_array_equal(loaded.dense_deltas()[0, 2], [0, 0.5, 0])


def test_loaded_arrays_are_read_only(saved):
    loaded = Character.load(saved)
    with pytest.raises(ValueError, match="read-only"):
        loaded.vertices[0, 0] = 1.0


def test_missing_file_is_named(tmp_path):
    with pytest.raises(TablesError, match=r"nothere\.npz: file: does not exist"):
        load_tables(tmp_path / "nothere.npz")


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, 0.99])
def test_truncated_file_is_refused(saved, tmp_path, keep):
    data = saved.read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(TablesError, match="truncated.npz"):
        Character.load(bad)


def test_garbled_bytes_are_refused(saved, tmp_path):
    data = bytearray(saved.read_bytes())
    rng = np.random.default_rng(1)
    # flip bytes inside the compressed payload (after the first local header)
    for pos in rng.integers(60, len(data) - 200, size=40):
        data[pos] ^= 0xFF
    bad = tmp_path / "garbled.npz"
    bad.write_bytes(bytes(data))
    with pytest.raises(TablesError, match="garbled.npz"):
        Character.load(bad)


def test_not_a_zip_is_refused(tmp_path):
    bad = tmp_path / "text.npz"
    bad.write_text("hello, I am not tables")
    with pytest.raises(TablesError, match="not a tables file"):
        load_tables(bad)


def test_pickled_section_is_refused_and_never_unpickled(saved, tmp_path):
    class Boom:
        def __reduce__(self):
            return (exec, ("raise SystemExit('unpickled!')",))

    evil = np.empty(1, dtype=object)
    evil[0] = Boom()
    bad = rewrite(saved, tmp_path / "pickled.npz", arrays={"pivot": evil})
    with pytest.raises(TablesError, match=r"pickled.npz: pivot: holds pickled Python objects"):
        load_tables(bad)


def test_plain_pickle_file_is_refused(tmp_path):
    bad = tmp_path / "plain.npz"
    bad.write_bytes(pickle.dumps({"vertices": np.zeros((3, 3))}))
    with pytest.raises(TablesError, match="not a tables file"):
        load_tables(bad)


def test_newer_schema_version_is_refused_with_advice(saved, tmp_path):
    manifest = manifest_of(saved)
    manifest["schema_version"] = SCHEMA_VERSION + 1
    bad = rewrite(saved, tmp_path / "newer.npz", manifest=manifest)
    with pytest.raises(TablesError, match=r"newer.npz: manifest.schema_version: .*newer facepuppet"):
        load_tables(bad)


def test_wrong_kind_is_refused(saved, tmp_path):
    manifest = manifest_of(saved)
    manifest["kind"] = "actor-of-the-future"
    bad = rewrite(saved, tmp_path / "kind.npz", manifest=manifest)
    with pytest.raises(TablesError, match=r"manifest.kind: expected 'character'"):
        Character.load(bad)


def test_wrong_shape_against_manifest_is_refused(saved, tmp_path):
    bad = rewrite(saved, tmp_path / "shape.npz", arrays={"vertices": np.zeros((4, 2), np.float32)})
    with pytest.raises(TablesError, match=r"shape.npz: vertices: manifest says shape \[4, 3\]"):
        load_tables(bad)


def test_wrong_shape_against_schema_is_refused(saved, tmp_path):
    manifest = manifest_of(saved)
    manifest["sections"]["vertex_color"]["shape"] = [5, 3]
    bad = rewrite(saved, tmp_path / "dims.npz", manifest=manifest,
                  arrays={"vertex_color": np.zeros((5, 3), np.float32)})
    with pytest.raises(TablesError, match=r"vertex_color: axis 0 is n_vertices = 5, but section 'vertices' says n_vertices = 4"):
        load_tables(bad)


def test_wrong_dtype_is_refused(saved, tmp_path):
    manifest = manifest_of(saved)
    manifest["sections"]["triangles"]["dtype"] = "float32"
    bad = rewrite(saved, tmp_path / "dtype.npz", manifest=manifest,
                  arrays={"triangles": np.zeros((2, 3), np.float32)})
    with pytest.raises(TablesError, match=r"triangles: dtype must be uint32, found float32"):
        load_tables(bad)


def test_missing_and_unlisted_sections_are_refused(saved, tmp_path):
    bad = rewrite(saved, tmp_path / "missing.npz", drop={"pivot"})
    with pytest.raises(TablesError, match=r"pivot: listed in the manifest but missing"):
        load_tables(bad)
    bad = rewrite(saved, tmp_path / "extra.npz", extra={"smuggled": np.zeros(3)})
    with pytest.raises(TablesError, match=r"smuggled: is in the archive but not listed"):
        load_tables(bad)


def test_channel_count_must_match_shapes(saved, tmp_path):
    manifest = manifest_of(saved)
    manifest["channels"]["shapes"] = ["jawOpen"]
    bad = rewrite(saved, tmp_path / "channels.npz", manifest=manifest)
    with pytest.raises(TablesError, match=r"channels.shapes: has 1 names but n_shapes = 2"):
        load_tables(bad)


def test_non_finite_values_are_refused_on_save_and_load(saved, tmp_path):
    verts = np.zeros((4, 3), np.float32)
    verts[1, 1] = np.nan
    bad = rewrite(saved, tmp_path / "nan.npz", arrays={"vertices": verts})
    with pytest.raises(TablesError, match=r"nan.npz: vertices: contains NaN"):
        load_tables(bad)
    arrays = tiny_character()._arrays()
    arrays["vertices"] = verts
    with pytest.raises(TablesError, match=r"vertices: contains NaN"):
        save_tables(tmp_path / "out.npz", "character", arrays, units="cm",
                    channels={"shapes": ["a", "b"], "materials": ["m", "n"]})


def test_save_refuses_unknown_units_and_kinds(tmp_path):
    arrays = tiny_character()._arrays()
    with pytest.raises(TablesError, match=r"units: must be one of"):
        save_tables(tmp_path / "u.npz", "character", arrays, units="furlong")
    with pytest.raises(TablesError, match=r"kind: unknown kind 'spaceship'"):
        save_tables(tmp_path / "k.npz", "spaceship", arrays)


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path):
    path = tmp_path / "quad.npz"
    tiny_character().save(path)
    tiny_character().save(path)  # overwrite in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ["quad.npz"]


def test_character_validation_names_the_field():
    c = tiny_character()
    with pytest.raises(TablesError, match=r"triangles: index 7 out of range for 4 vertices"):
        Character(**{**c.__dict__, "triangles": np.array([[0, 1, 7]], dtype=np.uint32),
                     "triangle_material": np.zeros(1, np.uint16)})
    with pytest.raises(TablesError, match=r"vertex_color: axis 0 is n_vertices = 3"):
        Character(**{**c.__dict__, "vertex_color": np.zeros((3, 3), np.float32)})
