"""A minimal glTF 2.0 / GLB writer for tests: raw bytes in, buffer views and accessors out, JSON by hand.

Independent of the project's reader: it packs what the test gives it (NumPy
arrays with an explicit dtype), and the test writes the JSON fields it means
to exercise. ``glb_chunks`` is the tests' own GLB parser (header + chunks),
used to read the data kit's JSON without the reader under test.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

COMPONENT_TYPE = {np.dtype("int8"): 5120, np.dtype("uint8"): 5121, np.dtype("int16"): 5122,
                  np.dtype("uint16"): 5123, np.dtype("uint32"): 5125, np.dtype("float32"): 5126}
TYPE_OF_WIDTH = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class GltfBuilder:
    """Collects one binary buffer, buffer views and accessors; ``doc`` is the JSON to finish by hand."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.doc: dict = {"asset": {"version": "2.0", "generator": "facepuppet tests gltf_writer"},
                          "bufferViews": [], "accessors": []}

    def view(self, data: bytes, stride: int | None = None) -> int:
        """Append ``data`` (4-byte aligned) as a buffer view; its index."""
        while len(self.blob) % 4:
            self.blob.append(0)
        v = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if stride is not None:
            v["byteStride"] = stride
        self.blob.extend(data)
        self.doc["bufferViews"].append(v)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array: np.ndarray | None, *, kind: str | None = None, normalized: bool = False,
                 view: int | None = None, offset: int = 0, count: int | None = None,
                 dtype: str | None = None, sparse: dict | None = None, minmax: bool = False) -> int:
        """An accessor over ``array`` (a new tight view), or over an existing ``view`` at ``offset``."""
        if array is not None:
            array = np.ascontiguousarray(array)
            width = 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))
            dt = array.dtype
            if view is None:
                view = self.view(array.astype(dt.newbyteorder("<")).tobytes())
            count = len(array) if count is None else count
        else:
            dt = np.dtype(dtype)
            width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        a = {"componentType": COMPONENT_TYPE[np.dtype(dt)], "count": count, "type": kind or TYPE_OF_WIDTH[width]}
        if view is not None:
            a["bufferView"] = view
            if offset:
                a["byteOffset"] = offset
        if normalized:
            a["normalized"] = True
        if sparse is not None:
            a["sparse"] = sparse
        if minmax and array is not None:
            flat = array.reshape(len(array), -1)
            a["min"], a["max"] = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        self.doc["accessors"].append(a)
        return len(self.doc["accessors"]) - 1

    def sparse(self, indices: np.ndarray, values: np.ndarray) -> dict:
        """A ``sparse`` object for ``indices`` (uint8/16/32) and ``values`` (the accessor's dtype)."""
        iv = self.view(np.ascontiguousarray(indices).tobytes())
        vv = self.view(np.ascontiguousarray(values).tobytes())
        return {"count": len(indices), "indices": {"bufferView": iv, "componentType": COMPONENT_TYPE[indices.dtype]},
                "values": {"bufferView": vv}}

    def padded_blob(self) -> bytes:
        return bytes(self.blob) + b"\x00" * (-len(self.blob) % 4)

    def write_glb(self, path: Path) -> Path:
        doc = dict(self.doc, buffers=[{"byteLength": len(self.blob)}])
        return write_glb(path, doc, self.padded_blob())

    def write_gltf(self, path: Path, *, external: str | None = None) -> Path:
        """A ``.gltf`` with the buffer as a data URI, or as the file ``external`` beside it."""
        if external is None:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
        else:
            (path.parent / external).write_bytes(bytes(self.blob))
            uri = external
        doc = dict(self.doc, buffers=[{"byteLength": len(self.blob), "uri": uri}])
        path.write_text(json.dumps(doc), encoding="utf-8")
        return path


def write_glb(path: Path, doc: dict, bin_chunk: bytes | None) -> Path:
    """A GLB of ``doc`` and an optional BIN chunk (both padded to 4 bytes as the spec asks)."""
    j = json.dumps(doc).encode("utf-8")
    j += b" " * (-len(j) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j
    if bin_chunk is not None:
        b = bin_chunk + b"\x00" * (-len(bin_chunk) % 4)
        body += struct.pack("<II", len(b), 0x004E4942) + b
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


def glb_chunks(data: bytes) -> tuple[dict, bytes | None]:
    """(JSON, BIN chunk) of GLB bytes, parsed here without the project's reader."""
    assert data[:4] == b"glTF"
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + jlen])
    at = 20 + jlen
    if at + 8 <= len(data):
        (blen,) = struct.unpack_from("<I", data, at)
        return doc, data[at + 8:at + 8 + blen]
    return doc, None


def read_doc(path: Path) -> tuple[dict, list[bytes]]:
    """The JSON and buffers (bytes) of a kit file, GLB or ``.gltf`` with data URIs."""
    data = path.read_bytes()
    if data[:4] == b"glTF":
        doc, blob = glb_chunks(data)
        return doc, [blob]
    doc = json.loads(data)
    return doc, [base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]


def raw_accessor(doc: dict, buffers: list[bytes], a: int) -> np.ndarray:
    """A plain (non-sparse, float32 or tight) accessor as float64 (count, n), for the tests' own arithmetic."""
    acc = doc["accessors"][a]
    bv = doc["bufferViews"][acc["bufferView"]]
    dt = {5126: "<f4", 5123: "<u2", 5125: "<u4", 5121: "u1"}[acc["componentType"]]
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
    size = np.dtype(dt).itemsize * n
    stride = bv.get("byteStride", size)
    start = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
    buf = buffers[bv["buffer"]]
    rows = [np.frombuffer(buf, dtype=dt, count=n, offset=start + i * stride) for i in range(acc["count"])]
    return np.array(rows, dtype=np.float64)
