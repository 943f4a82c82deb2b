"""glTF 2.0 containers and accessors: the GLB chunks, the JSON, the buffers, accessor decoding (NumPy).

Reads the file's bytes into a :class:`GltfFile` (the JSON document and the
buffers' bytes) and decodes accessors into arrays, following the glTF 2.0
specification (§5.1 accessors, §3.6.2 sparse accessors, §5.11 buffer views,
§4.4 GLB):

* a GLB is the 12-byte header (magic ``glTF``, version 2, total length), a
  JSON chunk, then optionally a BIN chunk; a ``.vrm`` is a GLB; anything else
  is read as a JSON ``.gltf``;
* buffers are the GLB's BIN chunk (buffer 0 without ``uri``), a ``data:`` URI
  (base64) or a file beside the ``.gltf``; the file itself and every URI are
  read by :mod:`.gltf_files` (regular files inside the glTF's folder only,
  sizes checked before reading);
* accessors of every component type, normalized or not (KHR_mesh_quantization
  is plain accessor decoding), with byte strides and sparse substitution, with
  or without a base buffer view.

Every size is checked against the declared byte lengths before anything is
allocated, so a count that would need gigabytes is refused, not attempted; an
accessor without a buffer view (zeros, perhaps with sparse substitutions) has
no bytes to be checked against, so it is held to :data:`MAX_UNBACKED_VALUES`.
Refusals are :class:`GltfError`: the file, the JSON field path and the
problem (``avatar.glb: accessors[3].count: …``).

The object model is plain ``json`` plus this parser, not pygltflib: the
reader needs accessor and sparse decoding of its own anyway, and checking the
container here lets every refusal name the exact field (pygltflib parses GLB
chunks without naming what is wrong and fills defaults silently).
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from facepuppet.offline.io.gltf_files import GltfError, Opened, open_image_uri, read_buffer_uri, read_gltf_bytes
from facepuppet.offline.io.mesh_format import sniff_mesh_format

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
N_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: The largest accessor the reader decodes (elements); far beyond any avatar, far below an allocation bomb.
MAX_ELEMENTS = 50_000_000
#: The most values (count x components) of an accessor without a buffer view, whose zeros no byte of the file
#: backs: 4 Mi values are 1.4 million VEC3 vertices in one morph target (a VRoid avatar's largest mesh has
#: ~30,000), and 32 MiB once decoded as float64.
MAX_UNBACKED_VALUES = 1 << 22

__all__ = ["GltfError", "GltfFile", "read_gltf_file", "is_gltf_file", "MAX_UNBACKED_VALUES"]


def is_gltf_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is glTF: a ``.gltf``/``.glb``/``.vrm`` name, or a regular file with GLB magic or glTF JSON
    text (nothing else is opened: a FIFO would block the sniff)."""
    path = Path(path)
    if path.suffix.lower() in (".gltf", ".glb", ".vrm"):
        return True
    if not path.is_file():
        return False
    try:
        found = sniff_mesh_format(path)
    except OSError:
        return False
    return found is not None and found.startswith("glTF")


@dataclass
class GltfFile:
    """A parsed glTF document: its JSON, whether it came as GLB, and the buffers (read on first use)."""

    path: Path
    doc: dict
    is_glb: bool
    bin_chunk: bytes | None
    _buffers: dict = field(default_factory=dict)
    external: list = field(default_factory=list)  # the external files read, for the input hash

    # -- errors and JSON fields -------------------------------------------
    def fail(self, where: str, problem: str) -> NoReturn:
        raise GltfError(self.path, where, problem)

    def items(self, key: str) -> list:
        """The top-level array ``key`` ([] when absent)."""
        value = self.doc.get(key, [])
        if not isinstance(value, list):
            self.fail(key, f"expected an array, found {type(value).__name__}")
        return value

    def obj(self, key: str, i: Any, where: str) -> dict:
        """Element ``i`` of the top-level array ``key``, checked to be an index and an object."""
        arr = self.items(key)
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(arr):
            self.fail(where, f"{i!r} is not an index into {key} (0..{len(arr) - 1})")
        o = arr[i]
        if not isinstance(o, dict):
            self.fail(f"{key}[{i}]", f"expected an object, found {type(o).__name__}")
        return o

    def get(self, o: dict, key: str, kind: type | tuple, where: str, default: Any = ..., ) -> Any:
        """``o[key]`` checked to be of ``kind``; ``default`` when absent (missing and no default: refused)."""
        if key not in o:
            if default is ...:
                self.fail(f"{where}.{key}", "missing (required by the glTF 2.0 specification)")
            return default
        value = o[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            ok = True
        if not ok:
            names = "/".join(k.__name__ for k in kinds)
            self.fail(f"{where}.{key}", f"expected {names}, found {json.dumps(value)[:40]}")
        return value

    def count(self, o: dict, key: str, where: str, default: Any = ..., minimum: int = 0) -> int:
        value = self.get(o, key, int, where, default)
        if value < minimum:
            self.fail(f"{where}.{key}", f"must be >= {minimum}, found {value}")
        return value

    def numbers(self, o: dict, key: str, n: int, where: str, default: Any) -> np.ndarray:
        """A fixed-length array of finite numbers (e.g. ``baseColorFactor``), float64."""
        value = o.get(key, default)
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.zeros(0)
        if arr.shape != (n,) or not np.isfinite(arr).all():
            self.fail(f"{where}.{key}", f"expected {n} finite numbers, found {json.dumps(value)[:60]}")
        return arr

    # -- buffers -----------------------------------------------------------
    def buffer(self, i: int, where: str) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        b = self.obj("buffers", i, where)
        where = f"buffers[{i}]"
        length = self.count(b, "byteLength", where, minimum=1)
        uri = self.get(b, "uri", str, where, None)
        if uri is None:
            if not self.is_glb or i != 0 or self.bin_chunk is None:
                self.fail(f"{where}.uri", "missing: only buffer 0 of a GLB with a BIN chunk may omit it")
            data = self.bin_chunk
            if len(data) < length:
                self.fail(f"{where}.byteLength", f"{length} bytes declared but the GLB BIN chunk has only "
                                                 f"{len(data)}")
            data = data[:length]
        else:
            data, file = read_buffer_uri(self.path, uri, where, length)
            if file is not None:
                self.external.append(file)
        self._buffers[i] = data
        return data

    def open_image(self, uri: str, where: str) -> Opened:
        """The image file or ``data:`` URI ``uri`` opened (see :mod:`.gltf_files`), for a ``with``."""
        opened = open_image_uri(self.path, uri, where)
        if opened.path is not None and opened.path not in self.external:
            self.external.append(opened.path)
        return opened

    def view_bytes(self, v: int, where: str) -> tuple[bytes, int, int, int | None]:
        """(buffer bytes, start, length, byteStride or None) of buffer view ``v``, bounds checked."""
        bv = self.obj("bufferViews", v, where)
        w = f"bufferViews[{v}]"
        buf_index = self.get(bv, "buffer", int, w)
        length = self.count(bv, "byteLength", w, minimum=1)
        offset = self.count(bv, "byteOffset", w, default=0)
        stride = self.get(bv, "byteStride", int, w, None)
        if stride is not None and not (4 <= stride <= 252 and stride % 4 == 0):
            self.fail(f"{w}.byteStride", f"must be a multiple of 4 in 4..252, found {stride}")
        data = self.buffer(buf_index, f"{w}.buffer")
        if offset + length > len(data):
            self.fail(w, f"bytes {offset}..{offset + length} run past the end of buffer {buf_index} "
                         f"({len(data)} bytes)")
        return data, offset, length, stride

    # -- accessors -----------------------------------------------------------
    def accessor(self, a: Any, where: str, *, as_float: bool = True) -> np.ndarray:
        """Accessor ``a`` decoded: (count, n) or (count,) for SCALAR (MAT4: (count, 4, 4) row-major).

        ``as_float``: float64 with normalized integers mapped to [0, 1] / [-1, 1] (the spec's
        formulas); else the integer values (for indices and joints).
        """
        acc = self.obj("accessors", a, where)
        w = f"accessors[{a}]"
        ctype = self.get(acc, "componentType", int, w)
        if ctype not in COMPONENT:
            self.fail(f"{w}.componentType", f"{ctype} is not a glTF component type ({sorted(COMPONENT)})")
        kind = self.get(acc, "type", str, w)
        if kind not in N_COMPONENTS:
            self.fail(f"{w}.type", f"{kind!r} is not one of {sorted(N_COMPONENTS)}")
        dtype = np.dtype(COMPONENT[ctype]).newbyteorder("<")
        n = N_COMPONENTS[kind]
        if kind in ("MAT2", "MAT3") and dtype.itemsize < 4:
            self.fail(f"{w}.type", f"{kind} of {dtype.itemsize}-byte components (column padding) is not read")
        count = self.count(acc, "count", w, minimum=1)
        if count > MAX_ELEMENTS:
            self.fail(f"{w}.count", f"{count} elements is more than this reader decodes ({MAX_ELEMENTS})")
        if "bufferView" not in acc and count * n > MAX_UNBACKED_VALUES:
            self.fail(f"{w}.count", f"{count} {kind} elements without a bufferView: more than the "
                                    f"{MAX_UNBACKED_VALUES} values an accessor of zeros may have here")
        normalized = self.get(acc, "normalized", bool, w, False)
        if normalized and ctype in (5125, 5126):
            self.fail(f"{w}.normalized", "only 8- and 16-bit integer accessors may be normalized")
        elem = n * dtype.itemsize
        if "bufferView" in acc:
            data, start, length, stride = self.view_bytes(self.get(acc, "bufferView", int, w), f"{w}.bufferView")
            off = self.count(acc, "byteOffset", w, default=0)
            if off % dtype.itemsize or (start + off) % dtype.itemsize:
                self.fail(f"{w}.byteOffset", f"{off} is not aligned to the {dtype.itemsize}-byte component")
            stride = stride or elem
            if stride < elem:
                self.fail(f"{w}", f"byteStride {stride} of its buffer view is less than its element ({elem} bytes)")
            need = off + stride * (count - 1) + elem
            if need > length:
                self.fail(f"{w}.count", f"{count} elements of {elem} bytes (stride {stride}) from byte {off} need "
                                        f"{need} bytes but bufferView {acc['bufferView']} has {length}")
            raw = np.ndarray((count, n), dtype=dtype, buffer=data, offset=start + off,
                             strides=(stride, dtype.itemsize)).copy()
        else:
            raw = np.zeros((count, n), dtype=dtype)
        if "sparse" in acc:
            self._sparse(acc["sparse"], raw, f"{w}.sparse", dtype, n)
        if as_float:
            out = raw.astype(np.float64)
            if normalized:
                info = np.iinfo(dtype)
                out = np.maximum(out / info.max, -1.0)
        else:
            if ctype == 5126:
                self.fail(f"{w}.componentType", "expected an integer accessor here, found float")
            out = raw.astype(np.int64)
        if kind == "MAT4":
            return out.reshape(count, 4, 4).transpose(0, 2, 1)  # column-major in the file
        if kind in ("MAT2", "MAT3"):
            k = 2 if kind == "MAT2" else 3
            return out.reshape(count, k, k).transpose(0, 2, 1)
        return out[:, 0] if n == 1 else out

    def _sparse(self, sparse: Any, raw: np.ndarray, w: str, dtype: np.dtype, n: int) -> None:
        if not isinstance(sparse, dict):
            self.fail(w, "expected an object")
        k = self.count(sparse, "count", w, minimum=1)
        if k > len(raw):
            self.fail(f"{w}.count", f"{k} substitutions for an accessor of {len(raw)} elements")
        ind = self.get(sparse, "indices", dict, w)
        val = self.get(sparse, "values", dict, w)
        ictype = self.get(ind, "componentType", int, f"{w}.indices")
        if ictype not in (5121, 5123, 5125):
            self.fail(f"{w}.indices.componentType", f"must be 5121, 5123 or 5125, found {ictype}")
        idtype = np.dtype(COMPONENT[ictype]).newbyteorder("<")
        indices = self._packed(ind, f"{w}.indices", idtype, k, 1)[:, 0].astype(np.int64)
        if np.any(indices >= len(raw)):
            bad = int(indices[np.argmax(indices >= len(raw))])
            self.fail(f"{w}.indices", f"index {bad} is past the accessor's {len(raw)} elements")
        if len(indices) > 1 and np.any(np.diff(indices) <= 0):
            self.fail(f"{w}.indices", "must strictly increase (glTF 2.0 §3.6.2.3)")
        raw[indices] = self._packed(val, f"{w}.values", dtype, k, n)

    def _packed(self, o: dict, w: str, dtype: np.dtype, count: int, n: int) -> np.ndarray:
        data, start, length, _ = self.view_bytes(self.get(o, "bufferView", int, w), f"{w}.bufferView")
        off = self.count(o, "byteOffset", w, default=0)
        need = off + count * n * dtype.itemsize
        if need > length:
            self.fail(w, f"{count} elements need {need} bytes but the buffer view has {length}")
        if (start + off) % dtype.itemsize:
            self.fail(f"{w}.byteOffset", "not aligned to its component size")
        return np.frombuffer(data, dtype=dtype, count=count * n, offset=start + off).reshape(count, n).copy()


def read_gltf_file(path: str | os.PathLike) -> GltfFile:
    """Parse the container of a ``.glb`` / ``.vrm`` / ``.gltf`` (no accessor is decoded yet)."""
    path = Path(path)
    data = read_gltf_bytes(path)
    if data[:4] == GLB_MAGIC:
        json_bytes, bin_chunk = _glb_chunks(path, data)
        is_glb = True
    else:
        json_bytes, bin_chunk, is_glb = data, None, False
    try:
        doc = json.loads(json_bytes.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise GltfError(path, "JSON chunk" if is_glb else "", f"not UTF-8 text (byte {exc.start})") from None
    except (ValueError, RecursionError) as exc:
        raise GltfError(path, "JSON chunk" if is_glb else "", f"not valid JSON ({str(exc)[:120]})") from None
    if not isinstance(doc, dict):
        raise GltfError(path, "JSON", f"the document must be an object, found {type(doc).__name__}")
    f = GltfFile(path, doc, is_glb, bin_chunk)
    asset = f.get(doc, "asset", dict, "")
    version = f.get(asset, "version", str, "asset")
    if not version.startswith("2."):
        f.fail("asset.version", f"{version!r}: only glTF 2.x is read")
    return f


def _glb_chunks(path: Path, data: bytes) -> tuple[bytes, bytes | None]:
    """(JSON chunk, BIN chunk or None) of a GLB, checking header, lengths and chunk types (glTF 2.0 §4.4)."""
    if len(data) < 12:
        raise GltfError(path, "GLB header", f"truncated: {len(data)} bytes, the header alone is 12")
    _, version, total = struct.unpack_from("<4sII", data)
    if version != 2:
        raise GltfError(path, "GLB header.version", f"{version}: only GLB version 2 is read")
    if total != len(data):
        raise GltfError(path, "GLB header.length", f"says {total} bytes but the file has {len(data)}"
                        + (" (truncated)" if total > len(data) else ""))
    chunks, at = [], 12
    while at < total:
        if at + 8 > total:
            raise GltfError(path, f"GLB chunk {len(chunks)}", f"truncated chunk header at byte {at}")
        length, kind = struct.unpack_from("<II", data, at)
        if at + 8 + length > total:
            raise GltfError(path, f"GLB chunk {len(chunks)}.chunkLength",
                            f"{length} bytes from byte {at + 8} run past the end of the file ({total} bytes)")
        if length % 4:
            raise GltfError(path, f"GLB chunk {len(chunks)}.chunkLength", f"{length} is not a multiple of 4")
        chunks.append((kind, data[at + 8:at + 8 + length]))
        at += 8 + length
    if not chunks or chunks[0][0] != CHUNK_JSON:
        found = f"0x{chunks[0][0]:08x}" if chunks else "no chunk"
        raise GltfError(path, "GLB chunk 0.chunkType", f"the first chunk must be JSON (0x4e4f534a), found {found}")
    bins = [c for k, c in chunks[1:] if k == CHUNK_BIN]
    if len(chunks) > 1 and chunks[1][0] != CHUNK_BIN and bins:
        raise GltfError(path, "GLB chunk 1.chunkType", "the BIN chunk must come right after the JSON chunk")
    if len(bins) > 1:
        raise GltfError(path, "GLB chunks", "more than one BIN chunk")
    return chunks[0][1].rstrip(b" \x00"), bins[0] if bins else None
