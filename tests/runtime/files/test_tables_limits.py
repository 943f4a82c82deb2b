"""Bounded work before refusal: forged tables files that inflate, pad or nest are refused early.

Built from the small real files in ``tests/runtime/files/data/tables_v1`` (written by
the format's own first code). The bombs check that refusal comes before the
decompression, by tracemalloc's peak (every NumPy array and ``bytes`` object
the loader makes is traced), not by wall-clock time.
"""

from __future__ import annotations

import json
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.bench.tables_bombs import inflating_section, padded_manifest, read_manifest, with_manifest
from facepuppet.runtime.files import tables as tables_mod
from facepuppet.runtime.files.tables import TablesError, load_tables
from facepuppet.runtime.model.character import Character

V1 = Path(__file__).parent / "data" / "tables_v1"
BOMB_BYTES = 96 << 20  # the tests' bomb: ~100 kB on disk, 96 MiB inflated
LOADERS = {"character": Character.load, "actor": Actor.load, "actor_pair": ActorPair.load}


def peak_while(fn) -> tuple[Exception | None, int]:
    """Run ``fn``; return the exception it raised (or None) and tracemalloc's peak in bytes."""
    tracemalloc.start()
    try:
        fn()
        caught = None
    except Exception as exc:  # noqa: BLE001 - the test inspects it
        caught = exc
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return caught, peak


def test_a_member_whose_header_disagrees_with_the_manifest_is_refused_before_inflating(tmp_path):
    bomb = inflating_section(V1 / "character.npz", tmp_path / "bomb.npz", "vertex_color", BOMB_BYTES)
    assert bomb.stat().st_size < BOMB_BYTES // 100
    caught, peak = peak_while(lambda: load_tables(bomb, "character"))
    assert isinstance(caught, TablesError)
    assert str(bomb) in str(caught) and "vertex_color" in str(caught) and "manifest says shape" in str(caught)
    assert peak < 8 << 20, f"the loader held {peak} bytes for a refused file"


def test_a_consistently_forged_huge_section_is_refused_by_the_schema_before_reading(tmp_path):
    bomb = inflating_section(V1 / "character.npz", tmp_path / "bomb.npz", "vertex_color", BOMB_BYTES,
                             consistent=True)
    caught, peak = peak_while(lambda: load_tables(bomb, "character"))
    assert isinstance(caught, TablesError) and str(bomb) in str(caught)
    assert "vertex_color" in str(caught)
    assert peak < 8 << 20


def test_a_section_over_the_size_limit_is_refused_unread(tmp_path, monkeypatch):
    src = V1 / "character.npz"
    sections = read_manifest(src)["sections"]
    sizes = {name: math.prod(meta["shape"]) * np.dtype(meta["dtype"]).itemsize for name, meta in sections.items()}
    largest = max(sizes.values())
    monkeypatch.setattr(tables_mod, "MAX_SECTION_BYTES", largest - 1)
    with pytest.raises(TablesError, match=r"character\.npz: (\w+): .*more than the limit") as caught:
        load_tables(src, "character")
    assert sizes[caught.value.field] == largest
    monkeypatch.setattr(tables_mod, "MAX_SECTION_BYTES", largest)
    assert load_tables(src, "character").kind == "character"


def test_a_manifest_padded_with_spaces_is_refused_unread(tmp_path):
    padded = padded_manifest(V1 / "character.npz", tmp_path / "padded.npz", 64 << 20)
    caught, peak = peak_while(lambda: load_tables(padded, "character"))
    assert isinstance(caught, TablesError)
    assert str(padded) in str(caught) and "manifest" in str(caught) and "limit" in str(caught)
    assert peak < 8 << 20


def test_a_deeply_nested_manifest_is_refused_with_the_file_named(tmp_path):
    manifest = json.dumps(read_manifest(V1 / "character.npz"))
    deep = manifest[:-1] + ', "deep": ' + "[" * 5000 + "]" * 5000 + "}"
    path = with_manifest(V1 / "character.npz", tmp_path / "deep.npz", deep.encode())
    with pytest.raises(TablesError, match=r"deep\.npz: manifest: nests 5001 levels deep"):
        load_tables(path, "character")


def test_a_5000_digit_schema_version_is_refused_with_the_file_named(tmp_path):
    manifest = json.dumps(read_manifest(V1 / "character.npz"))
    text = manifest.replace('"schema_version": 1', '"schema_version": ' + "9" * 5000)
    assert text != manifest
    path = with_manifest(V1 / "character.npz", tmp_path / "digits.npz", text.encode())
    with pytest.raises(TablesError, match=r"digits\.npz: manifest: "):
        load_tables(path, "character")


STRING_FIELDS = ("units", "kind", "input_hash", "created_by")
OBJECT_FIELDS = ("settings", "metrics", "channels", "dims", "sections")
WRONG_TYPES = ([(f, v) for f in OBJECT_FIELDS for v in ([1, 2], 3.5, "text", None)]
               + [(f, v) for f in STRING_FIELDS for v in ([1, 2], 3.5, {"a": 1}, None)])


@pytest.mark.parametrize("kind", sorted(LOADERS))
@pytest.mark.parametrize(("field", "value"), WRONG_TYPES, ids=[f"{f}={v!r}" for f, v in WRONG_TYPES])
def test_a_manifest_field_of_the_wrong_type_is_refused_by_every_loader(tmp_path, kind, field, value):
    manifest = read_manifest(V1 / f"{kind}.npz")
    manifest[field] = value
    path = with_manifest(V1 / f"{kind}.npz", tmp_path / "typed.npz", json.dumps(manifest).encode())
    with pytest.raises(TablesError, match=rf"typed\.npz: manifest\.{field}: must be"):
        LOADERS[kind](path)


@pytest.mark.parametrize("meta", [[3], {"shape": "x", "dtype": "float32"}, {"shape": [-1], "dtype": "float32"},
                                  {"shape": [3], "dtype": "object"}, {"shape": [True], "dtype": "float32"}])
def test_a_malformed_section_entry_is_refused_with_its_name(tmp_path, meta):
    manifest = read_manifest(V1 / "character.npz")
    manifest["sections"]["pivot"] = meta
    path = with_manifest(V1 / "character.npz", tmp_path / "sect.npz", json.dumps(manifest).encode())
    with pytest.raises(TablesError, match=r"sect\.npz: manifest\.sections\.pivot: must be"):
        Character.load(path)
