"""Reading MToon's outline / rim / UV animation, glTF's metallic-roughness and expressions' material binds.

Godette's values are checked against her JSON as the tests' own GLB parser reads it; built VRMs give the
binds; a bad bind is refused with exit 2 and the JSON path, through the real ``facepuppet import-rig``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from io import BytesIO

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.material_model import BIND_KINDS, BIND_SHAPE_PREFIX, OUTLINE_MODES
from facepuppet.runtime.render.material_binds import MaterialBinds

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from helpers.gltf_writer import glb_chunks, write_glb
from helpers.mtoon_vrms import ball_vrm


@pytest.mark.data
def test_godette_outlines_rim_and_backpack_metallic_roughness():
    path = need_shared("gltf", "Godette_vrm_v4.vrm")
    doc, _ = glb_chunks(path.read_bytes())
    c = read_gltf(path)
    mm = c.material_model
    for prop in doc["extensions"]["VRM"]["materialProperties"]:
        m = c.material_names.index(prop["name"])
        floats = prop["floatProperties"]
        if prop["shader"] != "VRM/MToon":
            assert mm.mtoon[m, 0] == OUTLINE_MODES["none"]
            continue
        assert mm.mtoon[m, 0] == floats["_OutlineWidthMode"] == 2
        assert mm.mtoon[m, 1] == pytest.approx(0.01 * floats["_OutlineWidth"])  # three-vrm's factor
        assert mm.mtoon[m, 5] == pytest.approx(floats["_OutlineLightingMix"])  # colour mode 1: mixed
        assert mm.mtoon[m, 10] == pytest.approx(floats["_RimFresnelPower"])
    backpack = c.material_names.index("Backpack")
    pbr = doc["materials"][backpack]["pbrMetallicRoughness"]
    assert "metallicFactor" not in pbr and "metallicRoughnessTexture" in pbr
    assert tuple(mm.pbr[backpack]) == (1.0, 1.0, 0.0, 1.0)  # glTF's default factors, its texture, lit by them
    image = mm.image(0)
    assert image.shape[:2] == (doc_image_size(doc, pbr["metallicRoughnessTexture"]["index"], path))
    # the look keeps only colour textures: the base colour ones
    assert len(c.look.texture_names) == len({m["pbrMetallicRoughness"]["baseColorTexture"]["index"]
                                             for m in doc["materials"]})


def doc_image_size(doc: dict, texture: int, path) -> tuple[int, int]:
    _, blob = glb_chunks(path.read_bytes())
    view = doc["bufferViews"][doc["images"][doc["textures"][texture]["source"]]["bufferView"]]
    start = view.get("byteOffset", 0)
    with Image.open(BytesIO(blob[start:start + view["byteLength"]])) as im:
        return im.size[1], im.size[0]


@pytest.mark.parametrize("version", ["1.0", "0.x"])
def test_colour_bind_gets_a_shape_of_its_own_and_survives_a_save(tmp_path, version):
    c = read_gltf(ball_vrm(tmp_path / "ball.vrm", version=version, tint=(0.0, 0.5, 1.0, 1.0)))
    assert c.shape_names == (BIND_SHAPE_PREFIX + "Tint",)
    shapes, weights = c.expressions.binds(c.expressions.names.index("Tint"))
    assert shapes.tolist() == [0] and weights.tolist() == [1.0]
    mm = c.material_model
    assert mm.bind_shape.tolist() == [0] and mm.bind_target.tolist() == [[0, BIND_KINDS["color"]]]
    np.testing.assert_allclose(mm.bind_value, [[0.0, 0.5, 1.0, 1.0]])
    c.save(tmp_path / "ball.npz")
    back = Character.load(tmp_path / "ball.npz")
    for name, arr in c.material_model.arrays().items():
        np.testing.assert_array_equal(back.material_model.arrays()[name], arr, err_msg=name)


def test_binds_add_up_as_three_vrm_applies_them(tmp_path):
    c = read_gltf(ball_vrm(tmp_path / "ball.vrm", base=(0.2, 0.2, 0.2, 1.0), tint=(1.0, 0.2, 0.2, 1.0)))
    binds = MaterialBinds(c)
    assert binds.update(np.array([0.5], np.float32)).tolist() == [0]
    np.testing.assert_allclose(binds.rows.base_color[0], [0.6, 0.2, 0.2, 1.0], atol=1e-6)
    assert binds.update(np.array([0.5], np.float32)).tolist() == []  # the same weight: nothing to upload
    binds.update(np.array([0.0], np.float32))
    np.testing.assert_allclose(binds.rows.base_color[0], c.look.base_color[0], atol=1e-6)


def test_a_bad_material_colour_bind_is_refused_by_its_json_path(tmp_path):
    path = ball_vrm(tmp_path / "ball.vrm")
    doc, blob = glb_chunks(path.read_bytes())
    doc["extensions"]["VRMC_vrm"]["expressions"]["custom"]["Tint"]["materialColorBinds"][0]["type"] = "glow"
    write_glb(path, doc, blob)
    done = subprocess.run([sys.executable, "-m", "facepuppet", "import-rig", str(path), "-o",
                           str(tmp_path / "x.npz")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "ball.vrm" in done.stderr and "expressions.custom.Tint.materialColorBinds[0].type" in done.stderr
    assert not (tmp_path / "x.npz").exists()
    assert json.dumps("glow") in done.stderr or "glow" in done.stderr


def _paths(value, path: tuple = ()):
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, path + (i,))


@pytest.mark.parametrize("version", ["1.0", "0.x"])
def test_every_wrong_type_in_the_material_parts_is_read_or_refused_naming_the_file(tmp_path, version):
    # the MToon outline / rim / UV fields, the width texture and the material binds: a value of each wrong type
    # at each of their paths reads, or is refused by the project's error naming the file; never another exception
    path = ball_vrm(tmp_path / "ball.vrm", version=version, half_width_texture=version == "1.0",
                    rim=(0.5, 0.5, 0.5))
    doc, blob = glb_chunks(path.read_bytes())
    roots = [("materials",), ("extensions", "VRMC_vrm", "expressions")] if version == "1.0" else \
        [("extensions", "VRM", "materialProperties"), ("extensions", "VRM", "blendShapeMaster")]
    forged_file, bugs, n = tmp_path / "forged.vrm", [], 0
    for root in roots:
        at = doc
        for k in root:
            at = at[k]
        for sub in _paths(at):
            for value in ([], {}, "x", 1.5, -1, None, True, 1e308):
                forged_doc = json.loads(json.dumps(doc))
                target = forged_doc
                full = root + sub
                for k in full[:-1]:
                    target = target[k]
                target[full[-1]] = value
                write_glb(forged_file, forged_doc, blob)
                n += 1
                try:
                    read_gltf(forged_file)
                except FacepuppetError as exc:
                    if not str(exc).startswith(str(forged_file)):
                        bugs.append(f"{full} = {value!r}: the refusal does not name the file: {exc}")
                except Exception as exc:  # noqa: BLE001 - any other exception is the bug looked for
                    bugs.append(f"{full} = {value!r}: {type(exc).__name__}: {exc}")
    assert n > 200
    assert not bugs, f"{len(bugs)} of {n}:\n" + "\n".join(bugs[:30])
