"""Hostile glTF files, forged by construction: what a stranger's avatar may hold to read, hang or exhaust.

Each forger ``forge(folder) -> Path`` writes one small file (and what it
points at: a secret beside the folder, a symlink, a FIFO) under ``folder`` and
returns the path to give ``import-rig`` and ``check-gltf``. Every one of them
must be refused (exit 2, the file and the JSON path named) without reading
outside the model's folder, in bounded memory and time. The benchmark
(``bench gltf-bombs``, :mod:`.gltf_bombs_bench`) and the file fuzz of the
tests share these forgers, so what is measured is what is tested.

The files are built from the JSON up, not by mutating a real avatar: each one
is the smallest file that carries its attack, so a refusal can only be for
that attack. A case whose bytes are big when decoded (an 8000×8000 PNG, an
accessor of 50 million elements) stays small on disk: zeros compress, and an
accessor without a buffer view is zeros by the spec.
"""

from __future__ import annotations

import base64
import functools
import json
import os
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.offline.io.gltf.write import encode_glb

#: One triangle, float32, the positions every forged mesh draws.
TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
#: The side of the forged textures: under the 8192² a single image may have, so only a total budget refuses them.
TEXTURE_SIDE = 8000
#: What the secret outside the model's folder holds: recognisable if it ever comes out of a reader.
SECRET = b"SECRET-outside-the-model-folder!" * 4


def _asset() -> dict:
    return {"version": "2.0", "generator": "facepuppet gltf_bombs (a forged hostile file)"}


def _data_uri(blob: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")


def _triangle_doc(uri: str, byte_length: int = TRIANGLE.nbytes) -> dict:
    """One triangle drawn from buffer 0 at ``uri``: its POSITION accessor's min/max are the triangle's, so a
    checker that reads the buffer shows what it read where they differ."""
    return {
        "asset": _asset(), "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "body"}],
        "meshes": [{"name": "face", "primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": TRIANGLE.min(axis=0).tolist(), "max": TRIANGLE.max(axis=0).tolist()}],
        "bufferViews": [{"buffer": 0, "byteLength": TRIANGLE.nbytes}],
        "buffers": [{"uri": uri, "byteLength": byte_length}],
    }


def _write_json(path: Path, doc: dict | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    text = doc if isinstance(doc, str) else json.dumps(doc, separators=(",", ":"))  # NaN written as NaN
    path.write_text(text, encoding="utf-8")
    return path


def _model(folder: Path) -> Path:
    """The model's own folder inside ``folder`` (so a ``..`` has somewhere to climb to that the forger owns)."""
    model = folder / "model"
    model.mkdir(parents=True, exist_ok=True)
    return model


def sound_triangle(folder: Path) -> Path:
    """The sound file every forgery is measured against: one triangle, its buffer a data URI."""
    return _write_json(_model(folder) / "triangle.gltf", _triangle_doc(_data_uri(TRIANGLE.tobytes())))


# -- reading outside the folder ------------------------------------------------------------------------------
def parent_passwd(folder: Path) -> Path:
    """A buffer uri climbing to ``/etc/passwd``."""
    return _write_json(_model(folder) / "passwd.gltf", _triangle_doc("../../../../../../etc/passwd"))


def parent_secret(folder: Path) -> Path:
    """A buffer uri ``../SECRET.bin``: the file beside the model's folder."""
    model = _model(folder)
    (folder / "SECRET.bin").write_bytes(SECRET)
    return _write_json(model / "secret.gltf", _triangle_doc("../SECRET.bin"))


def symlink_outside(folder: Path) -> Path:
    """A buffer inside the folder that is a symlink to a file outside it."""
    outside = folder / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    (outside / "secret.bin").write_bytes(SECRET)
    link = _model(folder) / "buffer.bin"
    link.unlink(missing_ok=True)
    link.symlink_to((outside / "secret.bin").resolve())
    return _write_json(link.parent / "symlink.gltf", _triangle_doc("buffer.bin"))


def dev_zero(folder: Path) -> Path:
    """A buffer uri naming ``/dev/zero``: endless bytes for a reader that reads to the end."""
    return _write_json(_model(folder) / "devzero.gltf", _triangle_doc("/dev/zero"))


def symlink_dev_zero(folder: Path) -> Path:
    """A buffer inside the folder that is a symlink to ``/dev/zero``."""
    link = _model(folder) / "zero.bin"
    link.unlink(missing_ok=True)
    link.symlink_to("/dev/zero")
    return _write_json(link.parent / "zerolink.gltf", _triangle_doc("zero.bin"))


def fifo(folder: Path) -> Path:
    """A buffer inside the folder that is a FIFO: opening it blocks until a writer comes, which none will."""
    pipe = _model(folder) / "pipe.bin"
    if not pipe.exists():
        os.mkfifo(pipe)
    return _write_json(pipe.parent / "fifo.gltf", _triangle_doc("pipe.bin"))


def nul_uri(folder: Path) -> Path:
    """A buffer uri with a NUL byte in it (the OS refuses the name; the reader must say which file and field)."""
    return _write_json(_model(folder) / "nul.gltf", _triangle_doc("buffer\x00.bin"))


# -- sizes declared ----------------------------------------------------------------------------------------------
def huge_accessor(folder: Path) -> Path:
    """A POSITION accessor without a buffer view (zeros by the spec) and ``count`` 50,000,000."""
    doc = _triangle_doc(_data_uri(TRIANGLE.tobytes()))
    doc["accessors"] = [{"componentType": 5126, "count": 50_000_000, "type": "VEC3", "min": [0, 0, 0],
                         "max": [0, 0, 0]}]
    return _write_json(_model(folder) / "huge_accessor.gltf", doc)


@functools.lru_cache(maxsize=2)
def blank_png(side: int = TEXTURE_SIDE) -> bytes:
    """A black RGB PNG of ``side``² texels (8000²: 192 MB decoded, about 190 KB compressed), written by hand:
    the scanlines are deflated a row at a time, so forging it never holds the decoded image."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    deflate = zlib.compressobj(9)
    row = bytes(1 + 3 * side)  # filter byte 0, then black texels
    idat = b"".join(deflate.compress(row) for _ in range(side)) + deflate.flush()
    header = struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0)  # 8-bit RGB, deflate, no interlace
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def big_textures(folder: Path, n: int = 4) -> Path:
    """A GLB whose one mesh has ``n`` primitives over one triangle, each with its own material and its own
    8000×8000 PNG texture (each under the per-image limit; together past any sane budget)."""
    png = blank_png()
    blob = bytearray(TRIANGLE.tobytes())
    views = [{"buffer": 0, "byteLength": TRIANGLE.nbytes}]
    for _ in range(n):
        blob.extend(b"\0" * (-len(blob) % 4))
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(png)})
        blob.extend(png)
    doc = {
        "asset": _asset(), "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": k} for k in range(n)]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}} for k in range(n)],
        "textures": [{"source": k} for k in range(n)],
        "images": [{"bufferView": k + 1, "mimeType": "image/png"} for k in range(n)],
        "bufferViews": views, "buffers": [{"byteLength": len(blob)}],
    }
    path = _model(folder) / f"textures{n}.glb"
    path.write_bytes(encode_glb(doc, bytes(blob)))
    return path


def sixteen_textures(folder: Path) -> Path:
    """:func:`big_textures` with sixteen textures."""
    return big_textures(folder, 16)


# -- structure: counts and depth ----------------------------------------------------------------------------------
def _mesh_doc() -> dict:
    """One triangle mesh with its buffer as a data URI; the caller adds the nodes and scenes."""
    doc = _triangle_doc(_data_uri(TRIANGLE.tobytes()))
    del doc["nodes"], doc["scenes"], doc["scene"]
    return doc


def same_name_nodes(folder: Path, n: int = 30_001) -> Path:
    """``n`` root nodes all named "Bone" (the first draws the triangle): names a character keeps unique."""
    doc = _mesh_doc()
    doc["nodes"] = [{"name": "Bone"} for _ in range(n)]
    doc["nodes"][0]["mesh"] = 0
    doc.update(scene=0, scenes=[{"nodes": list(range(n))}])
    return _write_json(_model(folder) / f"same_name_nodes{n}.gltf", doc)


def mesh_instances(folder: Path, n: int = 3_000) -> Path:
    """``n`` nodes instancing one mesh (each instance is stored, and its name made unique)."""
    doc = _mesh_doc()
    doc["nodes"] = [{"mesh": 0, "translation": [float(i), 0.0, 0.0]} for i in range(n)]
    doc.update(scene=0, scenes=[{"nodes": list(range(n))}])
    return _write_json(_model(folder) / f"mesh_instances{n}.gltf", doc)


def own_attribute_primitives(folder: Path, n: int = 4_000) -> Path:
    """One mesh of ``n`` primitives, each with its own POSITION accessor (so none shares its vertices)."""
    doc = _mesh_doc()
    doc["accessors"] = [dict(doc["accessors"][0]) for _ in range(n)]
    doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": k}} for k in range(n)]}]
    doc.update(nodes=[{"mesh": 0}], scene=0, scenes=[{"nodes": [0]}])
    return _write_json(_model(folder) / f"own_attribute_primitives{n}.gltf", doc)


def deep_chain(folder: Path, n: int = 60_000) -> Path:
    """``n`` nodes, each the only child of the one before; the deepest draws the triangle."""
    doc = _mesh_doc()
    doc["nodes"] = [{"children": [i + 1]} for i in range(n - 1)] + [{"mesh": 0}]
    doc.update(scene=0, scenes=[{"nodes": [0]}])
    return _write_json(_model(folder) / f"deep_chain{n}.gltf", doc)


def deep_json(folder: Path, depth: int = 100_000) -> Path:
    """A document whose ``extras`` nests arrays ``depth`` deep (JSON allows it; a recursive parser does not)."""
    text = '{"asset":{"version":"2.0"},"extras":' + "[" * depth + "]" * depth + "}"
    return _write_json(_model(folder) / "deep_json.gltf", text)


# -- values ---------------------------------------------------------------------------------------------------------
def nan_weights(folder: Path) -> Path:
    """A mesh with one morph target whose default ``weights`` is NaN (Python's JSON reads the bare ``NaN``)."""
    doc = _mesh_doc()
    delta = TRIANGLE * np.float32(0.1)
    blob = TRIANGLE.tobytes() + delta.tobytes()
    doc["buffers"] = [{"uri": _data_uri(blob), "byteLength": len(blob)}]
    doc["bufferViews"].append({"buffer": 0, "byteOffset": TRIANGLE.nbytes, "byteLength": delta.nbytes})
    doc["accessors"].append({"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3",
                             "min": delta.min(axis=0).tolist(), "max": delta.max(axis=0).tolist()})
    doc["meshes"] = [{"name": "face", "weights": [float("nan")],
                      "primitives": [{"attributes": {"POSITION": 0}, "targets": [{"POSITION": 1}]}]}]
    doc.update(nodes=[{"mesh": 0}], scene=0, scenes=[{"nodes": [0]}])
    return _write_json(_model(folder) / "nan_weights.gltf", doc)


#: Every forged case by name, in the issue's order: what the benchmark runs and the file fuzz refuses.
FORGERIES: dict[str, Callable[[Path], Path]] = {
    "parent_passwd": parent_passwd,
    "parent_secret": parent_secret,
    "symlink_outside": symlink_outside,
    "dev_zero": dev_zero,
    "symlink_dev_zero": symlink_dev_zero,
    "huge_accessor": huge_accessor,
    "four_textures": big_textures,
    "sixteen_textures": sixteen_textures,
    "same_name_nodes": same_name_nodes,
    "mesh_instances": mesh_instances,
    "own_attribute_primitives": own_attribute_primitives,
    "fifo": fifo,
    "deep_chain": deep_chain,
    "nul_uri": nul_uri,
    "nan_weights": nan_weights,
    "deep_json": deep_json,
}

_URI = r"buffers\[0\]"
#: The JSON path (a regular expression) each case's refusal names, in the message or in check-gltf's list.
REFUSAL_NAMES: dict[str, str] = {
    "parent_passwd": _URI, "parent_secret": _URI, "symlink_outside": _URI, "dev_zero": _URI,
    "symlink_dev_zero": _URI, "fifo": _URI, "nul_uri": _URI,
    "huge_accessor": r"accessors\[0\]",
    "four_textures": r"images|textures", "sixteen_textures": r"images|textures",
    "same_name_nodes": r"nodes", "mesh_instances": r"nodes|mesh", "own_attribute_primitives": r"primitives",
    "deep_chain": r"nodes", "nan_weights": r"meshes\[0\]\.weights", "deep_json": r"JSON",
}
