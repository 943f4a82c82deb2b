"""gltf_files: import-rig and check-gltf read a glTF's files under the same rules, and refuse the same files.

Each hostile file is given to both commands: ``import-rig`` must exit 2 with one line naming the file and the
JSON path, ``check-gltf`` must list the problem at that path (and exit 2). A FIFO or a device could make a
reader wait or read forever, so those cases run the real command in a subprocess, with a timeout as a hang guard.
"""

from __future__ import annotations

import io
import json
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.read_materials import MAX_TEXTURE_SIDE, MAX_TEXTURE_TEXELS
from facepuppet.offline.io.gltf.write import encode_glb
from facepuppet.offline.io.gltf_check import check_gltf
from facepuppet.offline.io.gltf_check_accessors import DECODE_BUDGET_FACTOR
from facepuppet.offline.io.gltf_container import MAX_UNBACKED_VALUES, GltfError
from facepuppet.offline.io.gltf_files import MAX_FILE_BYTES
from helpers.gltf_writer import GltfBuilder, read_doc

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
HANG_GUARD_S = 120  # a generous bound for a command that used to block forever


def model(folder: Path, name: str = "m.gltf") -> tuple[Path, dict]:
    """A one-triangle .gltf in ``folder`` with its buffer in ``tri.bin`` beside it; (path, its JSON)."""
    folder.mkdir(parents=True, exist_ok=True)
    b = GltfBuilder()
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": b.accessor(TRI, minmax=True)}}]}]
    b.doc["nodes"], b.doc["scenes"], b.doc["scene"] = [{"mesh": 0}], [{"nodes": [0]}], 0
    path = b.write_gltf(folder / name, external="tri.bin")
    return path, json.loads(path.read_text())


def with_buffer_uri(tmp_path: Path, uri: str) -> Path:
    path, doc = model(tmp_path / "model")
    doc["buffers"][0]["uri"] = uri
    path.write_text(json.dumps(doc))
    return path


def import_rig(path: Path, tmp_path: Path, capsys) -> tuple[int, str]:
    code = main(["import-rig", str(path), "-o", str(tmp_path / "out.npz")])
    return code, capsys.readouterr().err


def check(path: Path, capsys) -> tuple[int, str]:
    code = main(["check-gltf", str(path)])
    return code, capsys.readouterr().out


def both_refuse(path: Path, tmp_path: Path, capsys, where: str, why: str) -> str:
    """import-rig: exit 2, one line naming the file, ``where`` and ``why``; check-gltf: exit 2 with that problem
    (its output returned)."""
    code, err = import_rig(path, tmp_path, capsys)
    assert code == 2, err
    assert "Traceback" not in err
    assert f"{path}: {where}: " in err and why in err, err
    code, out = check(path, capsys)
    assert code == 2
    assert any(line.startswith(f"{path}: {where}: ") and why in line for line in out.splitlines()), out
    return out


def run_command(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "facepuppet", *argv], capture_output=True, text=True,
                          timeout=HANG_GUARD_S)


# -- the resolver -------------------------------------------------------------------------------------------


def test_a_buffer_beside_the_file_is_read_by_both(tmp_path, capsys):
    path, _ = model(tmp_path / "model")
    assert check_gltf(path) == []
    np.testing.assert_array_equal(read_gltf(path).vertices, TRI)


@pytest.mark.parametrize("uri", ["../SECRET.bin", "sub/../../SECRET.bin", "%2E%2E/SECRET.bin", "/etc/passwd",
                                 "../../../../../../../../etc/passwd"])
def test_a_uri_climbing_out_of_the_folder_or_absolute_is_refused_by_both(tmp_path, capsys, uri):
    (tmp_path / "SECRET.bin").write_bytes(TRI.tobytes())
    (tmp_path / "model" / "sub").mkdir(parents=True)
    path = with_buffer_uri(tmp_path, uri)
    out = both_refuse(path, tmp_path, capsys, "buffers[0].uri", "inside the folder of the glTF")
    assert "the data's" not in out   # nothing read from the secret comes out as accessor min/max


def test_a_symlink_inside_the_folder_pointing_out_of_it_is_refused_by_both(tmp_path, capsys):
    (tmp_path / "SECRET.bin").write_bytes(TRI.tobytes())
    path = with_buffer_uri(tmp_path, "link.bin")
    (path.parent / "link.bin").symlink_to(tmp_path / "SECRET.bin")
    both_refuse(path, tmp_path, capsys, "buffers[0].uri", "inside the folder of the glTF")


def test_a_symlink_inside_the_folder_to_a_file_inside_is_read(tmp_path, capsys):
    path = with_buffer_uri(tmp_path, "link.bin")
    (path.parent / "link.bin").symlink_to(path.parent / "tri.bin")
    assert check_gltf(path) == []
    np.testing.assert_array_equal(read_gltf(path).vertices, TRI)


def test_a_symlink_to_dev_zero_is_refused_by_both_without_reading_it(tmp_path):
    path = with_buffer_uri(tmp_path, "zero.bin")
    (path.parent / "zero.bin").symlink_to("/dev/zero")
    for argv in (["import-rig", str(path), "-o", str(tmp_path / "o.npz")], ["check-gltf", str(path)]):
        done = run_command(*argv)
        text = done.stderr + done.stdout
        assert done.returncode == 2 and "Traceback" not in text
        assert f"{path}: buffers[0].uri: " in text and "inside the folder" in text


def test_a_fifo_in_the_folder_is_refused_by_both_at_once(tmp_path):
    path = with_buffer_uri(tmp_path, "fifo.bin")
    os.mkfifo(path.parent / "fifo.bin")  # no writer ever opens it: a blocking open would wait forever
    for argv in (["import-rig", str(path), "-o", str(tmp_path / "o.npz")], ["check-gltf", str(path)]):
        done = run_command(*argv)
        text = done.stderr + done.stdout
        assert done.returncode == 2 and "Traceback" not in text
        assert f"{path}: buffers[0].uri: " in text and "a FIFO, not a regular file" in text


def test_a_folder_named_as_a_buffer_is_refused_by_both(tmp_path, capsys):
    path = with_buffer_uri(tmp_path, "sub")
    (path.parent / "sub").mkdir()
    both_refuse(path, tmp_path, capsys, "buffers[0].uri", "a folder, not a regular file")


@pytest.mark.parametrize("uri,why", [("tri\x00.bin", "NUL"), ("tri%00.bin", "NUL"), ("tri%FF.bin", "not a UTF-8"),
                                     ("tri\udc80.bin", "not a UTF-8")])
def test_a_uri_with_a_nul_or_undecodable_text_is_refused_naming_the_file_and_field(tmp_path, capsys, uri, why):
    path = with_buffer_uri(tmp_path, uri)
    both_refuse(path, tmp_path, capsys, "buffers[0].uri", why)


def test_a_file_shorter_than_its_byte_length_is_refused_before_reading(tmp_path, capsys):
    path, doc = model(tmp_path / "model")
    doc["buffers"][0]["byteLength"] = 4000
    doc["bufferViews"][0]["byteLength"] = 4000
    path.write_text(json.dumps(doc))
    both_refuse(path, tmp_path, capsys, "buffers[0].byteLength", "4000 bytes declared but file 'tri.bin' has only 36")


def test_a_byte_length_past_the_cap_is_refused(tmp_path, capsys):
    path, doc = model(tmp_path / "model")
    doc["buffers"][0]["byteLength"] = MAX_FILE_BYTES + 1
    path.write_text(json.dumps(doc))
    both_refuse(path, tmp_path, capsys, "buffers[0].byteLength", f"1..{MAX_FILE_BYTES} bytes")


def test_a_data_uri_larger_than_its_byte_length_is_refused_before_decoding(tmp_path, capsys):
    path, doc = model(tmp_path / "model")
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + "A" * 4_000_000
    path.write_text(json.dumps(doc))
    both_refuse(path, tmp_path, capsys, "buffers[0].uri", "a data URI of 3000000 bytes, more than the 36")


def test_a_url_is_refused_by_both(tmp_path, capsys):
    path = with_buffer_uri(tmp_path, "http://127.0.0.1:9/tri.bin")
    both_refuse(path, tmp_path, capsys, "buffers[0].uri", "not URLs")


def test_an_image_uri_out_of_the_folder_is_refused_by_both(tmp_path, capsys):
    (tmp_path / "face.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    path, doc = model(tmp_path / "model")
    doc["images"] = [{"uri": "../face.png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    path.write_text(json.dumps(doc))
    both_refuse(path, tmp_path, capsys, "images[0].uri", "inside the folder of the glTF")


# -- the file given -----------------------------------------------------------------------------------------


def test_check_gltf_of_dev_zero_or_a_fifo_is_refused_at_once(tmp_path):
    fifo = tmp_path / "model.vrm"
    os.mkfifo(fifo)
    for name, what in (("/dev/zero", "a character device"), (str(fifo), "a FIFO")):
        done = run_command("check-gltf", name)
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert f"{name}: file: is {what}, not a regular file" in done.stdout
    done = run_command("import-rig", str(fifo), "-o", str(tmp_path / "o.npz"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"{fifo}: is a FIFO, not a regular file" in done.stderr


# -- sizes declared beyond what the file holds ----------------------------------------------------------------


def test_an_accessor_of_50_million_zeros_is_refused_before_allocating(tmp_path, capsys):
    path, doc = model(tmp_path / "model")
    doc["accessors"].append({"componentType": 5126, "count": 50_000_000, "type": "VEC3"})
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 1
    path.write_text(json.dumps(doc))
    both_refuse(path, tmp_path, capsys, "accessors[1].count", f"the {MAX_UNBACKED_VALUES} values")


def test_an_accessor_of_zeros_within_the_cap_is_still_read(tmp_path):
    b = GltfBuilder()
    sparse = b.sparse(np.array([1], np.uint8), np.array([[0, 0, 0.5]], np.float32))
    delta = b.accessor(None, kind="VEC3", dtype="float32", count=3, sparse=sparse)
    b.doc["accessors"][delta].update(min=[0, 0, 0], max=[0, 0, 0.5])
    pos = b.accessor(TRI, minmax=True)
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": pos}, "targets": [{"POSITION": delta}]}]}]
    b.doc["nodes"], b.doc["scenes"] = [{"mesh": 0}], [{"nodes": [0]}]
    path = b.write_glb(tmp_path / "t.glb")
    assert check_gltf(path) == []
    np.testing.assert_array_equal(read_gltf(path).dense_deltas()[0], [[0, 0, 0], [0, 0, 0.5], [0, 0, 0]])


def blank_png(side: int) -> bytes:
    """A grey ``side`` x ``side`` PNG, compressed row by row (a blank 8000x8000 is ~64 KB; never held whole)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    z = zlib.compressobj(9)
    row = b"\x00" + b"\x80" * side   # filter byte 0, then the row's grey values
    idat = b"".join(z.compress(row) for _ in range(side)) + z.flush()
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def png_8000():
    return blank_png(8000)


def textured(tmp_path: Path, png: bytes, n_images: int) -> Path:
    """A GLB with one triangle and ``n_images`` materials, each with its own texture and image of ``png``."""
    b = GltfBuilder()
    pos = b.accessor(TRI, minmax=True)
    uv = b.accessor(np.zeros((3, 2), np.float32))
    view = b.view(png)
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv}, "material": 0}]}]
    b.doc["nodes"], b.doc["scenes"] = [{"mesh": 0}], [{"nodes": [0]}]
    b.doc["images"] = [{"bufferView": view, "mimeType": "image/png"} for _ in range(n_images)]
    b.doc["textures"] = [{"source": i} for i in range(n_images)]
    b.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}} for i in range(n_images)]
    return b.write_glb(tmp_path / "textured.glb")


def test_four_8000_square_textures_are_refused_from_their_headers(tmp_path, capsys, png_8000):
    assert 4 * 8000 * 8000 > MAX_TEXTURE_TEXELS >= 2 * 8000 * 8000
    path = textured(tmp_path, png_8000, 4)
    assert path.stat().st_size < 400_000
    code, err = import_rig(path, tmp_path, capsys)
    assert code == 2 and "Traceback" not in err
    assert f"{path}: images[2]: 8000x8000 texels bring the used textures to 192000000 texels" in err
    # structurally sound, but check-gltf says (from the headers: no pixel decoded) why the importer refuses it
    problems = check_gltf(path)
    assert len(problems) == 1 and problems[0].startswith("images[2]: 8000x8000 texels bring the images to "
                                                         "192000000 texels, more than 134217728")


def test_an_image_wider_than_the_cap_is_refused(tmp_path, capsys):
    png = blank_png(MAX_TEXTURE_SIDE + 8)
    code, err = import_rig(textured(tmp_path, png, 1), tmp_path, capsys)
    assert code == 2 and f"images[0]: {MAX_TEXTURE_SIDE + 8}x{MAX_TEXTURE_SIDE + 8} texels: larger than" in err


def test_images_within_the_budget_are_decoded_into_one_texel_array(tmp_path):
    c = read_gltf(textured(tmp_path, blank_png(64), 3))
    lk = c.look
    assert lk.texture_pixels.shape == (3 * 64 * 64, 4)
    assert lk.texture_info[:, :3].tolist() == [[0, 64, 64], [4096, 64, 64], [8192, 64, 64]]
    np.testing.assert_array_equal(lk.image(2), np.full((64, 64, 4), [128, 128, 128, 255], np.uint8))


@pytest.mark.data
def test_every_image_of_the_data_kit_fits_the_caps():
    kit = need_shared("gltf")
    total_max = 0
    for path in sorted(kit.glob("*.vrm")):
        doc, buffers = read_doc(path)
        total = 0
        for img in doc.get("images", []):
            v = doc["bufferViews"][img["bufferView"]]
            blob = buffers[v["buffer"]][v.get("byteOffset", 0):v.get("byteOffset", 0) + v["byteLength"]]
            with Image.open(io.BytesIO(blob)) as im:
                assert max(im.size) <= MAX_TEXTURE_SIDE
                total += im.width * im.height
        total_max = max(total_max, total)
    assert 0 < total_max <= MAX_TEXTURE_TEXELS // 16


def test_the_error_type_is_the_containers(tmp_path):
    path = with_buffer_uri(tmp_path, "../x.bin")
    with pytest.raises(GltfError, match=r"m\.gltf: buffers\[0\]\.uri: '\.\./x\.bin': the file must be inside"):
        read_gltf(path)


def test_accessors_laid_over_the_same_bytes_thousands_of_times_stop_at_the_decode_budget(tmp_path):
    b = GltfBuilder()
    view = b.view(np.zeros(16 << 10, np.float32).tobytes())   # 64 KiB
    for _ in range(4000):   # 250 MiB of decoding asked from a 64 KiB buffer
        b.accessor(None, kind="SCALAR", dtype="float32", view=view, count=16 << 10)
    path = b.write_glb(tmp_path / "overlaid.glb")
    found = check_gltf(path)
    assert found == [f"accessors: decode more than {DECODE_BUDGET_FACTOR} times the buffers' bytes (they overlap "
                     "over and over); the data of the rest is not checked"]


def test_a_buffer_shorter_than_declared_is_not_read_past_its_end(tmp_path):
    b = GltfBuilder()
    b.accessor(np.arange(3000, dtype=np.float32))
    doc = dict(b.doc, buffers=[{"byteLength": 12000}])
    path = tmp_path / "short.glb"
    path.write_bytes(encode_glb(doc, bytes(b.blob[:400])))   # the BIN chunk holds 400 of the 12,000 bytes
    found = check_gltf(path)
    assert found == ["buffers[0].byteLength: 12000 but the BIN chunk holds 400 bytes (it may be at most 3 bytes of "
                     "padding longer)"]
