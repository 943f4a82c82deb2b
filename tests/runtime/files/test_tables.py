"""The tables contract: round trip, and refusal of every kind of bad file."""

from __future__ import annotations

import io
import json
import pickle
import zipfile

import numpy as np
import pytest

from facepuppet.runtime.files.tables import (
    Section,
    TableSchema,
    TablesError,
    coerce,
    hash_inputs,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)
from facepuppet.runtime.model.character import CHARACTER_SCHEMA, Character, sparse_deltas


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
    assert manifest["schema_version"] == CHARACTER_SCHEMA.version == 3  # 2: optional glTF parts; 3: kept images
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
    manifest["schema_version"] = CHARACTER_SCHEMA.version + 1
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
    with pytest.raises(TablesError,
                       match=r"vertex_color: axis 0 is n_vertices = 5, but section 'vertices' says n_vertices = 4"):
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


# -- the public contract: schemas, coerce, validate, naming_file ---------------------------------------------------

TINY_SCHEMA = register_schema(TableSchema(
    kind="test_tiny",
    sections={
        "points": Section("float32", ("n_points", 3), "positions"),
        "offsets": Section("int64", ("n_groups+1",), "group starts"),
        "extra": Section("uint8", ("n_points",), "a flag per point", optional=True),
    },
    channels=("groups",),
    channel_dims={"groups": "n_groups"},
    version=2,
))


def tiny_arrays() -> dict[str, np.ndarray]:
    return {"points": np.zeros((5, 3), np.float32), "offsets": np.array([0, 2, 5], np.int64)}


def test_validate_returns_the_named_dimensions():
    dims = validate(TINY_SCHEMA, tiny_arrays(), {"groups": ["a", "b"]})
    assert dims == {"n_points": 5, "n_groups": 2}
    dims = validate(TINY_SCHEMA, {**tiny_arrays(), "extra": np.ones(5, np.uint8)}, {"groups": ["a", "b"]})
    assert dims == {"n_points": 5, "n_groups": 2}


@pytest.mark.parametrize("change, message", [
    ({"points": None}, r"<tables>: points: missing section \(kind 'test_tiny' requires it\)"),
    ({"smuggled": np.zeros(3, np.float32)}, r"<tables>: smuggled: not a section of kind 'test_tiny'"),
    ({"points": np.zeros((5, 3))}, r"points: dtype must be float32, found float64"),
    ({"extra": np.ones(4, np.uint8)}, r"extra: axis 0 is n_points = 4, but section 'points' says n_points = 5"),
    ({"points": np.full((5, 3), np.inf, np.float32)}, r"points: contains NaN or infinity"),
])
def test_validate_refuses_with_the_field(change, message):
    arrays = {k: v for k, v in {**tiny_arrays(), **change}.items() if v is not None}
    with pytest.raises(TablesError, match=message):
        validate(TINY_SCHEMA, arrays, {"groups": ["a", "b"]})


def test_validate_checks_the_channel_groups():
    with pytest.raises(TablesError, match=r"channels.groups: missing channel name list"):
        validate(TINY_SCHEMA, tiny_arrays(), {})
    with pytest.raises(TablesError, match=r"channels.groups: has 3 names but n_groups = 2"):
        validate(TINY_SCHEMA, tiny_arrays(), {"groups": ["a", "b", "c"]})
    with pytest.raises(TablesError, match=r"in.npz: channels.groups: duplicate names \['a'\]"):
        validate(TINY_SCHEMA, tiny_arrays(), {"groups": ["a", "a"]}, "in.npz")


def test_coerce_casts_to_the_section_dtypes_read_only():
    out = coerce(TINY_SCHEMA, {"points": [[1, 2, 3]] * 5, "offsets": np.array([0, 2, 5], np.int32)})
    assert out["points"].dtype == np.float32 and out["offsets"].dtype == np.int64
    assert out["points"].flags.c_contiguous and not out["points"].flags.writeable
    fits = np.zeros((5, 3), np.float32)
    assert coerce(TINY_SCHEMA, {"points": fits})["points"] is fits  # no copy where it already fits
    with pytest.raises(TablesError, match=r"<tables>: nothing: not a section of kind 'test_tiny'"):
        coerce(TINY_SCHEMA, {"nothing": np.zeros(1)})


def test_sections_refuse_what_no_file_can_hold():
    with pytest.raises(ValueError, match=r"Section dtype: expected one of .*, got 'complex64'"):
        Section("complex64", (3,))
    with pytest.raises(ValueError, match=r"Section shape: expected ints and names .*, got 'n-points'"):
        Section("float32", ("n-points",))


def test_schemas_refuse_a_bad_version_or_an_unknown_channel_dimension():
    with pytest.raises(ValueError, match=r"TableSchema 'x' version: expected an int >= 1, got 0"):
        TableSchema("x", {"a": Section("float32", ("n",))}, version=0)
    with pytest.raises(ValueError, match=r"TableSchema 'x' channel_dims\['names'\]: 'm' is no section's dimension"):
        TableSchema("x", {"a": Section("float32", ("n",))}, channels=("names",), channel_dims={"names": "m"})


def test_a_kind_writes_its_own_schema_version_and_refuses_newer(tmp_path):
    path = save_tables(tmp_path / "tiny.npz", "test_tiny", tiny_arrays(), channels={"groups": ["a", "b"]})
    assert load_tables(path, "test_tiny").manifest["schema_version"] == 2
    manifest = manifest_of(path)
    manifest["schema_version"] = 3
    bad = rewrite(path, tmp_path / "tiny3.npz", manifest=manifest)
    with pytest.raises(TablesError, match=r"tiny3.npz: manifest.schema_version: is 3, .* reads test_tiny schema "
                                          r"versions up to 2\. Upgrade facepuppet"):
        load_tables(bad)


def test_save_takes_a_tables_metadata_and_explicit_fields_win(tmp_path):
    metadata = {"settings": {"a": 1}, "metrics": {"rms": 0.5}, "input_hash": "sha256:ab"}
    path = save_tables(tmp_path / "m.npz", "test_tiny", tiny_arrays(), channels={"groups": ["a", "b"]},
                       metadata=metadata, settings={"b": 2})
    loaded = load_tables(path)
    assert loaded.metadata == {"settings": {"b": 2}, "metrics": {"rms": 0.5}, "input_hash": "sha256:ab"}
    loaded.metadata["settings"]["c"] = 3  # fresh copies: the manifest is untouched
    assert loaded.settings == {"b": 2}


def test_naming_file_names_the_file_in_refusals_about_memory():
    with pytest.raises(TablesError, match=r"^some.npz: points: bad$"):
        with naming_file("some.npz"):
            raise TablesError(None, "points", "bad")
    with pytest.raises(TablesError, match=r"^other.npz: points: bad$"):  # a file already named stays
        with naming_file("some.npz"):
            raise TablesError("other.npz", "points", "bad")


def test_a_class_refusal_on_load_names_the_file(tmp_path):
    from facepuppet.runtime.actuation.actor import Actor

    from helpers.small_actors import make_actor

    path = make_actor().save(tmp_path / "actor.npz")
    bad = rewrite(path, tmp_path / "bounds.npz", arrays={"s_lower": np.full(4, 0.1, np.float32)})
    with pytest.raises(TablesError, match=r"bounds.npz: s_lower/s_upper: bounds must contain s = 0"):
        Actor.load(bad)


def test_every_table_class_refuses_non_finite_arrays_when_built():
    from facepuppet.runtime.actuation.actor import Actor

    from helpers.small_actors import make_actor

    actor = make_actor()
    neutral = np.array(actor.neutral)
    neutral[2, 1] = np.nan
    with pytest.raises(TablesError, match=r"<tables>: neutral: contains NaN or infinity"):
        Actor(**{**actor.__dict__, "neutral": neutral})
    c = tiny_character()
    colors = np.full((4, 3), 0.5, np.float32)
    colors[0, 0] = np.inf
    with pytest.raises(TablesError, match=r"<tables>: vertex_color: contains NaN or infinity"):
        Character(**{**c.__dict__, "vertex_color": colors})


def test_a_saved_table_has_the_permissions_a_plain_file_would(tmp_path):
    # save_tables wrote through a bare mkstemp file and so left every table 0600 (unreadable by a show
    # machine's other accounts); it must give what open() gives under the same umask.
    plain = tmp_path / "plain.bin"
    plain.write_bytes(b"")
    saved = tiny_character().save(tmp_path / "perm.npz")
    assert saved.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left behind
