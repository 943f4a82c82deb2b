"""Wrong JSON types everywhere: check-gltf lists problems and never raises; the importer reads or refuses by name.

A VRM written by the project (0.x and 1.0) is forged systematically: the value at every JSON path (each
element of an array of objects, the first element of an array of numbers) is replaced by each of
``[]``, ``{}``, ``"x"``, 1.5, -1, null and true. For each forged file ``check_gltf`` must return (a list of
problems, or none), and ``read_gltf`` must return a character or raise the project's refusal naming the file
(what ``import-rig`` turns into exit 2 and one line). Anything else (AttributeError, TypeError, KeyError, ...)
is a bug, listed with the path and the value that caused it.
"""

from __future__ import annotations

import base64
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from facepuppet.runtime.errors import FacepuppetError

from facepuppet.offline.io.gltf import structure_limits
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import build_gltf, encode_glb
from facepuppet.offline.io.gltf_check import MAX_PROBLEMS, check_gltf
from helpers.gltf_characters import parts_character

WRONG = ([], {}, "x", 1.5, -1, None, True)


def json_paths(value, path: tuple = ()) -> Iterator[tuple]:
    """Every path into ``value``; of an array of plain values only the first element (they are all alike)."""
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from json_paths(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            if i and not isinstance(v, (dict, list)):
                break
            yield from json_paths(v, path + (i,))


def forged(doc: dict, path: tuple, value) -> dict:
    if not path:
        return value
    out = json.loads(json.dumps(doc))
    at = out
    for key in path[:-1]:
        at = at[key]
    at[path[-1]] = value
    return out


def show(path: tuple) -> str:
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in path) or "(the document)"


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["vrm0", "vrm1"])
def test_every_wrong_type_at_every_path_is_a_problem_or_a_refusal_naming_the_file(tmp_path, fmt):
    doc, blob, _ = build_gltf(parts_character(source_format=fmt), fmt)
    blob = bytes(blob)
    file = tmp_path / "forged.vrm"
    bugs, n = [], 0
    for path in json_paths(doc):
        for value in WRONG:
            file.write_bytes(encode_glb(forged(doc, path, value), blob))
            n += 1
            try:
                problems = check_gltf(file)
                assert isinstance(problems, list)
            except Exception as exc:  # noqa: BLE001 - any exception is the bug this test looks for
                bugs.append(f"check-gltf {show(path)} = {json.dumps(value)}: {type(exc).__name__}: {exc}")
            try:
                read_gltf(file)
            except FacepuppetError as exc:
                if not str(exc).startswith(str(file)):
                    bugs.append(f"import {show(path)} = {json.dumps(value)}: the refusal does not name the file: {exc}")
            except Exception as exc:  # noqa: BLE001
                bugs.append(f"import {show(path)} = {json.dumps(value)}: {type(exc).__name__}: {exc}")
    assert n > 3000
    assert not bugs, f"{len(bugs)} of {n} forged files:\n" + "\n".join(bugs[:40])


@pytest.mark.parametrize("key", ["buffers[0].uri", "buffers[0].byteLength", "images[0].uri", "images[1].uri"])
def test_wrong_types_of_a_uri_or_a_byte_length_in_a_gltf_are_problems_or_refusals(tmp_path, key):
    doc, blob, _ = build_gltf(parts_character(), "glb")
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    array, rest = key.split("[", 1)
    index, field = int(rest.split("]")[0]), rest.split(".")[1]
    file = tmp_path / "forged.gltf"
    for value in (*WRONG, "", ".", "data:", "data:x;base64,!!", "a\x00b", "%ff", "//host/x", "C:/x.bin", "/dev/zero"):
        forged_doc = json.loads(json.dumps(doc))
        forged_doc[array][index][field] = value
        file.write_text(json.dumps(forged_doc))
        assert isinstance(check_gltf(file), list)
        try:
            read_gltf(file)
        except FacepuppetError as exc:
            assert str(exc).startswith(f"{file}: {key.split('.')[0]}"), exc


def test_a_60000_deep_node_chain_is_checked_without_recursion(tmp_path, monkeypatch):
    n = 60_000
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "scene": 0,
           "nodes": [{"children": [i + 1]} for i in range(n - 1)] + [{}]}
    path = tmp_path / "deep.gltf"
    path.write_text(json.dumps(doc))
    assert check_gltf(path) == [f"nodes: {n} nodes; a file may have at most {structure_limits.MAX_NODES} (beyond "
                                "what facepuppet imports)"]
    # past the importer's limits, check-gltf's own walk of the hierarchy: linear, no recursion
    monkeypatch.setattr(structure_limits, "MAX_NODES", 10 * n)
    monkeypatch.setattr(structure_limits, "MAX_DEPTH", 10 * n)
    assert check_gltf(path) == []
    doc["nodes"][-1] = {"children": [n // 2]}   # now the lower half is a cycle with two parents at its top
    path.write_text(json.dumps(doc))
    found = check_gltf(path)
    assert f"nodes[{n - 1}].children[0]: node {n // 2} already has parent {n // 2 - 1}" in found
    doc["nodes"][-1] = {"children": [0]}   # the whole chain is a cycle: 60,000 nodes in it
    path.write_text(json.dumps(doc))
    found = check_gltf(path)
    assert found[:2] == ["nodes[0]: its parents form a cycle", "nodes[1]: its parents form a cycle"]
    assert found[-1].startswith("(more problems not listed")


def test_json_nested_past_the_parser_is_a_problem(tmp_path):
    path = tmp_path / "nested.gltf"
    path.write_text('{"asset": {"version": "2.0"}, "extras": ' + "[" * 100_000 + "]" * 100_000 + "}")
    assert check_gltf(path) == ["JSON: nested too deeply to be read"]


def test_problems_are_listed_at_most_max_problems_times(tmp_path, monkeypatch):
    monkeypatch.setattr(structure_limits, "MAX_MESHES", 10 * MAX_PROBLEMS)  # within the importer's limits
    doc = {"asset": {"version": "2.0"}, "nodes": [{"mesh": 5} for _ in range(3 * MAX_PROBLEMS)]}
    path = tmp_path / "many.gltf"
    path.write_text(json.dumps(doc))
    found = check_gltf(path)
    assert len(found) == MAX_PROBLEMS + 1 and found[-1].startswith("(more problems not listed")


def test_a_value_of_the_wrong_type_is_named_by_its_path(tmp_path):
    doc, blob, _ = build_gltf(parts_character(), "vrm0")
    groups = doc["extensions"]["VRM"]["blendShapeMaster"]["blendShapeGroups"]
    groups[0]["binds"] = [[1, 2]]
    path = Path(tmp_path / "binds.vrm")
    path.write_bytes(encode_glb(doc, bytes(blob)))
    assert "extensions.VRM.blendShapeMaster.blendShapeGroups[0].binds[0]: [1, 2]: must be an object" \
        in check_gltf(path)
