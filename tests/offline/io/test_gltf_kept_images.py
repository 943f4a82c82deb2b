"""Every texture an avatar file has is kept, byte for byte: a 2048² normal map of noise (PNG cannot shrink it)
goes through import, the character table and export unchanged.

The VRM is built here: the built test character exported as VRM 1.0, its JSON and binary chunk then given a
normal map on a material by the tests' own GLB writer (not the exporter's code).
"""

from __future__ import annotations

import base64
import copy
import dataclasses
import io
from pathlib import Path

import numpy as np
from PIL import Image

from facepuppet.runtime.model.character import Character

from facepuppet.offline.io.gltf import kept_parts
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from helpers.gltf_characters import parts_character
from helpers.gltf_validator import ERROR, WARNING, codes, need_validator, problems, validate
from helpers.gltf_writer import glb_chunks, write_glb

SIDE = 2048


def noise_png(side: int) -> bytes:
    """An RGB PNG of uniform noise: as large as its pixels (12 MB at 2048²), far past the old 1.5 MB cap."""
    pixels = np.random.default_rng(11).integers(0, 256, (side, side, 3), dtype=np.uint8)
    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="PNG", compress_level=1)
    return out.getvalue()


def with_normal_map(tmp_path: Path, png: bytes) -> Path:
    """The built character as a VRM 1.0 whose first material has ``png`` as its normal texture."""
    base = export_character(parts_character(source_format="vrm1"), tmp_path / "base.vrm", vrm=1).path
    doc, blob = glb_chunks(base.read_bytes())
    blob = bytearray(blob) + bytes(-len(blob) % 4)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(png)})
    blob += png
    doc["buffers"][0]["byteLength"] = len(blob)
    doc["images"].append({"name": "noise_normal", "mimeType": "image/png", "bufferView": len(doc["bufferViews"]) - 1})
    doc["textures"].append({"source": len(doc["images"]) - 1})
    doc["materials"][0]["normalTexture"] = {"index": len(doc["textures"]) - 1, "scale": 0.7}
    return write_glb(tmp_path / "normal_map.vrm", doc, bytes(blob))


def written_normal_map(path: Path) -> tuple[dict, bytes]:
    """The exported file's first material's normal texture info and its image's bytes."""
    doc, blob = glb_chunks(path.read_bytes())
    info = doc["materials"][0]["normalTexture"]
    view = doc["bufferViews"][doc["images"][doc["textures"][info["index"]]["source"]]["bufferView"]]
    start = view.get("byteOffset", 0)
    return info, blob[start:start + view["byteLength"]]


def test_a_2048_noise_normal_map_round_trips_byte_identical(tmp_path):
    png = noise_png(SIDE)
    assert len(png) > 8_000_000  # the old cap was 1_500_000 bytes in all
    c = read_gltf(with_normal_map(tmp_path, png))
    assert not [w for w in c.source["warnings"] if "not kept" in w]
    entry = next(e for e in c.source["kept"]["images"] if e["name"] == "noise_normal")
    assert "data" not in entry and c.kept_images.image(entry["index"]) == png  # in the table, not the JSON
    back = Character.load(c.save(tmp_path / "avatar.npz"))  # through the character table
    for v in (1, 0):
        info, data = written_normal_map(export_character(back, tmp_path / f"out{v}.vrm", vrm=v).path)
        assert data == png and info["scale"] == 0.7, v


def test_an_image_past_the_bound_of_one_image_is_dropped_with_a_warning(tmp_path, monkeypatch):
    png = noise_png(256)
    monkeypatch.setattr(kept_parts, "MAX_KEPT_IMAGE_BYTES", len(png) - 1)
    c = read_gltf(with_normal_map(tmp_path, png))
    assert not [e for e in c.source["kept"]["images"] if e["name"] == "noise_normal"]
    assert any("not kept for export" in w and f"{len(png)} bytes" in w for w in c.source["warnings"])


def test_a_character_written_with_base64_kept_images_still_exports_them(tmp_path):
    """Before the kept images were a table section, their bytes were base64 in the entry (``data``)."""
    png = noise_png(64)
    c = read_gltf(with_normal_map(tmp_path, png))
    settings = copy.deepcopy(dict(c.metadata["settings"]))
    for entry in settings["source"]["kept"]["images"]:
        entry["data"] = base64.b64encode(c.kept_images.image(entry.pop("index"))).decode("ascii")
    old = dataclasses.replace(c, kept_images=None, metadata={**c.metadata, "settings": settings})
    back = Character.load(old.save(tmp_path / "old.npz"))
    assert back.kept_images is None
    _, data = written_normal_map(export_character(back, tmp_path / "out.vrm", vrm=1).path)
    assert data == png


def test_the_exports_with_the_kept_normal_map_are_valid(tmp_path):
    """The Khronos glTF-Validator on the built file and on its exports: 0 errors, no warning the built file did
    not have (VRM 0.x's extension name aside, which every 0.x file has)."""
    need_validator()
    built = with_normal_map(tmp_path, noise_png(256))
    c = read_gltf(built)
    outs = [export_character(c, tmp_path / f"v{v}.vrm", vrm=v).path for v in (0, 1)]
    original, *reports = validate(built, *outs)
    assert original["numErrors"] == 0, problems(original, ERROR)
    for v, report in zip((0, 1), reports):
        assert report["numErrors"] == 0, problems(report, ERROR)
        allowed = set(codes(original, WARNING)) | ({"INVALID_EXTENSION_NAME_FORMAT"} if v == 0 else set())
        assert set(codes(report, WARNING)) <= allowed, problems(report, WARNING)
