"""A structural validity check of a glTF 2.0 / GLB / VRM file, written from the glTF 2.0 specification.

``check_gltf(path)`` returns a list of problems, each "where: what" (empty when
the file is sound). It reads the file itself (no glTF library), so a problem
it reports is one of the file, not of a reader. What it checks:

* GLB container (spec §4.4): magic, version 2, the header's length equal to the
  file's, chunk lengths inside the file and multiples of 4, chunk starts
  4-byte aligned, the first chunk JSON (0x4E4F534A), a second BIN
  (0x004E4942) only once; the BIN chunk at least the buffer's byteLength and
  at most 3 bytes of padding more; the JSON UTF-8 and an object.
* required fields (asset.version, buffers[].byteLength, bufferViews[].buffer
  and byteLength, accessors[].componentType/count/type, meshes[].primitives,
  primitives[].attributes, skins[].joints, …) and their types.
* buffer views inside their buffer, byteStride 4..252 and a multiple of 4;
  accessors: valid componentType and type, byteOffset a multiple of the
  component size, the last element (with byteStride) inside the buffer view,
  sparse indices and values inside their views, sparse indices strictly
  increasing and below count.
* POSITION accessors (attributes and morph targets) have min and max, and any
  min/max given equal the data (float32).
* primitives: attribute counts equal, index values below the vertex count,
  indices a SCALAR of unsigned type; the same number of morph targets in every
  primitive of a mesh (and ``weights`` of that length).
* nodes: children, mesh, skin in range, no node with two parents, no cycle;
  skin joints are nodes, inverseBindMatrices a MAT4 float with a matrix per
  joint; JOINTS_0 values below the skin's joint count.
* scenes, textures (source, sampler), images (bufferView or uri, mimeType with
  a bufferView), material texture references in range.
* VRM 0.x (``extensions.VRM``) and 1.0 (``VRMC_vrm``): humanoid, firstPerson,
  expression binds and secondaryAnimation references to nodes, meshes and
  morph targets in range; materialProperties texture indices in range.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["check_gltf", "check_gltf_bytes"]

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_COLUMNS = {"MAT2": (2, 2), "MAT3": (3, 3), "MAT4": (4, 4)}
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


def check_gltf(path: str | os.PathLike) -> list[str]:
    """Problems of the glTF / GLB / VRM file at ``path`` (see the module doc); [] when none."""
    path = Path(path)
    return check_gltf_bytes(path.read_bytes(), base=path.parent, name=path.name)


def check_gltf_bytes(data: bytes, base: Path | None = None, name: str = "file") -> list[str]:
    """Problems of glTF / GLB bytes; ``base`` is the folder external buffers are read from."""
    c = _Checker(name, base)
    try:
        c.run(data)
    except _Stop:
        pass
    return c.problems


class _Stop(Exception):
    pass


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


class _Checker:
    def __init__(self, name: str, base: Path | None) -> None:
        self.name, self.base = name, base
        self.problems: list[str] = []
        self.buffers: list[bytes | None] = []

    def bad(self, where: str, what: str) -> None:
        self.problems.append(f"{where}: {what}")

    def stop(self, where: str, what: str) -> None:
        self.bad(where, what)
        raise _Stop

    # -- container --------------------------------------------------------------------------
    def run(self, data: bytes) -> None:
        bin_chunk = None
        if data[:4] == b"glTF":
            js, bin_chunk = self._glb(data)
        else:
            js = data
        try:
            doc = json.loads(js.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self.stop("JSON", f"not UTF-8 JSON ({str(exc)[:100]})")
        if not isinstance(doc, dict):
            self.stop("JSON", "the top level is not an object")
        self.doc = doc
        self._asset()
        self._buffers(bin_chunk, glb=data[:4] == b"glTF")
        self._views()
        self._accessors()
        self._meshes()
        self._nodes()
        self._skins()
        self._scenes()
        self._textures()
        self._vrm0()
        self._vrm1()

    def _glb(self, data: bytes) -> tuple[bytes, bytes | None]:
        if len(data) < 12:
            self.stop("GLB header", f"{len(data)} bytes; a GLB header is 12")
        magic, version, length = struct.unpack_from("<III", data, 0)
        if version != 2:
            self.bad("GLB header.version", f"{version}; must be 2")
        if length != len(data):
            self.bad("GLB header.length", f"{length} but the file has {len(data)} bytes")
        if length % 4:
            self.bad("GLB header.length", f"{length} is not a multiple of 4")
        end = min(length, len(data))
        off, chunks = 12, []
        while off < end:
            if off % 4:
                self.bad(f"GLB chunk {len(chunks)}", f"starts at byte {off}, not 4-byte aligned")
            if off + 8 > end:
                self.stop(f"GLB chunk {len(chunks)}", f"header at byte {off} runs past the end ({end})")
            clen, ctype = struct.unpack_from("<II", data, off)
            if clen % 4:
                self.bad(f"GLB chunk {len(chunks)}.chunkLength", f"{clen} is not a multiple of 4")
            if off + 8 + clen > end:
                self.stop(f"GLB chunk {len(chunks)}.chunkLength", f"{clen} bytes from byte {off + 8} run past the "
                                                                  f"end of the file ({end})")
            chunks.append((ctype, data[off + 8:off + 8 + clen]))
            off += 8 + clen
        if not chunks or chunks[0][0] != GLB_JSON:
            self.stop("GLB chunk 0.chunkType", "the first chunk must be JSON (0x4E4F534A)")
        bins = [i for i, (t, _) in enumerate(chunks) if t == GLB_BIN]
        if bins and bins[0] != 1:
            self.bad(f"GLB chunk {bins[0]}.chunkType", "the BIN chunk must be the second chunk")
        if len(bins) > 1:
            self.bad(f"GLB chunk {bins[1]}.chunkType", "more than one BIN chunk")
        if [i for i, (t, _) in enumerate(chunks) if t == GLB_JSON][1:]:
            self.bad("GLB chunks", "more than one JSON chunk")
        return chunks[0][1], (chunks[bins[0]][1] if bins else None)

    # -- helpers ----------------------------------------------------------------------------
    def items(self, key: str) -> list:
        v = self.doc.get(key, [])
        if not isinstance(v, list):
            self.bad(key, "must be an array")
            return []
        return v

    def index(self, obj: dict, key: str, array: str, where: str, required: bool = False) -> int | None:
        if key not in obj:
            if required:
                self.bad(f"{where}.{key}", "missing (required)")
            return None
        v = obj[key]
        n = len(self.items(array))
        if not _is_int(v) or not 0 <= v < n:
            self.bad(f"{where}.{key}", f"{v!r} is not an index into {array} ({n} entries)")
            return None
        return v

    def req(self, obj: dict, key: str, where: str, kind: type | tuple) -> Any:
        if key not in obj:
            self.bad(f"{where}.{key}", "missing (required)")
            return None
        v = obj[key]
        if not isinstance(v, kind) or (kind is int and isinstance(v, bool)):
            self.bad(f"{where}.{key}", f"{v!r} has the wrong type")
            return None
        return v

    def objects(self, key: str) -> list[tuple[int, dict, str]]:
        out = []
        for i, o in enumerate(self.items(key)):
            if isinstance(o, dict):
                out.append((i, o, f"{key}[{i}]"))
            else:
                self.bad(f"{key}[{i}]", "must be an object")
        return out

    # -- sections ---------------------------------------------------------------------------
    def _asset(self) -> None:
        asset = self.doc.get("asset")
        if not isinstance(asset, dict):
            self.bad("asset", "missing (required)")
            return
        v = self.req(asset, "version", "asset", str)
        if v is not None and not v.startswith("2."):
            self.bad("asset.version", f"{v!r}; this is a glTF 2.0 check")

    def _buffers(self, bin_chunk: bytes | None, glb: bool) -> None:
        for i, b, w in self.objects("buffers"):
            n = self.req(b, "byteLength", w, int)
            data = None
            if n is not None and n < 1:
                self.bad(f"{w}.byteLength", f"{n}; must be >= 1")
            uri = b.get("uri")
            if uri is None:
                if not (glb and i == 0):
                    self.bad(w, "no uri, and only the first buffer of a GLB may use the BIN chunk")
                elif bin_chunk is None:
                    self.bad(w, "refers to the GLB BIN chunk, but the file has none")
                else:
                    data = bin_chunk
                    if n is not None and not n <= len(bin_chunk) <= n + 3:
                        self.bad(f"{w}.byteLength", f"{n} but the BIN chunk holds {len(bin_chunk)} bytes "
                                                    "(it may be at most 3 bytes of padding longer)")
            elif isinstance(uri, str) and uri.startswith("data:"):
                try:
                    data = base64.b64decode(uri.split(",", 1)[1], validate=True)
                except (ValueError, IndexError):
                    self.bad(f"{w}.uri", "a data URI that is not base64")
            elif isinstance(uri, str) and self.base is not None and "://" not in uri and not Path(uri).is_absolute():
                try:
                    data = (self.base / uri).read_bytes()
                except OSError as exc:
                    self.bad(f"{w}.uri", f"{uri!r} cannot be read ({exc.strerror})")
            if data is not None and n is not None and len(data) < n:
                self.bad(f"{w}.byteLength", f"{n} but the data has {len(data)} bytes")
            self.buffers.append(data)

    def _views(self) -> None:
        self.view_ok: dict[int, dict] = {}
        buffers = self.items("buffers")
        for i, v, w in self.objects("bufferViews"):
            b = self.index(v, "buffer", "buffers", w, required=True)
            n = self.req(v, "byteLength", w, int)
            off = v.get("byteOffset", 0)
            if not _is_int(off) or off < 0:
                self.bad(f"{w}.byteOffset", f"{off!r}; must be an integer >= 0")
                continue
            stride = v.get("byteStride")
            if stride is not None and (not _is_int(stride) or not 4 <= stride <= 252 or stride % 4):
                self.bad(f"{w}.byteStride", f"{stride!r}; must be 4..252 and a multiple of 4")
            if b is None or n is None:
                continue
            if n < 1:
                self.bad(f"{w}.byteLength", f"{n}; must be >= 1")
            size = buffers[b].get("byteLength") if isinstance(buffers[b], dict) else None
            if _is_int(size) and off + n > size:
                self.bad(w, f"bytes {off}..{off + n} run past buffer {b}'s byteLength {size}")
                continue
            self.view_ok[i] = v

    def _view_bytes(self, vi: int) -> bytes | None:
        v = self.view_ok.get(vi)
        if v is None:
            return None
        data = self.buffers[v["buffer"]] if v["buffer"] < len(self.buffers) else None
        if data is None:
            return None
        off = v.get("byteOffset", 0)
        return data[off:off + v["byteLength"]]

    def _accessors(self) -> None:
        self.data: dict[int, np.ndarray | None] = {}
        self.acc_ok: dict[int, dict] = {}
        for i, a, w in self.objects("accessors"):
            ct = self.req(a, "componentType", w, int)
            n = self.req(a, "count", w, int)
            t = self.req(a, "type", w, str)
            ok = True
            if ct is not None and ct not in _COMPONENTS:
                self.bad(f"{w}.componentType", f"{ct} is not a glTF component type")
                ok = False
            if t is not None and t not in _WIDTH:
                self.bad(f"{w}.type", f"{t!r} is not SCALAR, VEC2..4 or MAT2..4")
                ok = False
            if n is not None and n < 1:
                self.bad(f"{w}.count", f"{n}; must be >= 1")
                ok = False
            if not ok or None in (ct, n, t):
                continue
            arr = self._read(a, w, ct, n, t)
            self.acc_ok[i] = a
            self.data[i] = arr
            for key in ("min", "max"):
                if key in a:
                    vals = a[key]
                    if not (isinstance(vals, list) and len(vals) == _WIDTH[t]):
                        self.bad(f"{w}.{key}", f"must be {_WIDTH[t]} numbers")
                        continue
                    if arr is not None:
                        flat = arr.reshape(n, -1).astype(np.float64)
                        if a.get("normalized") and ct != 5126:
                            flat = _normalize(flat, ct)
                        got = flat.min(axis=0) if key == "min" else flat.max(axis=0)
                        want = np.asarray(vals, dtype=np.float64)
                        if ct == 5126:
                            want, got = want.astype(np.float32), got.astype(np.float32)
                        if not np.allclose(got, want, rtol=1e-6, atol=1e-7):
                            self.bad(f"{w}.{key}", f"{vals} but the data's {key} is {[float(x) for x in got]}")

    def _read(self, a: dict, w: str, ct: int, n: int, t: str) -> np.ndarray | None:
        dtype = np.dtype(_COMPONENTS[ct]).newbyteorder("<")
        size = dtype.itemsize
        width = _WIDTH[t]
        cols = _COLUMNS.get(t)
        # matrix columns start on 4-byte boundaries (spec 3.6.2.4: MAT2/MAT3 of 1- and 2-byte components)
        col_bytes = cols[0] * size if cols else width * size
        col_stride = (col_bytes + 3) // 4 * 4 if cols else col_bytes
        elem = col_stride * (cols[1] if cols else 1)
        off = a.get("byteOffset", 0)
        if not _is_int(off) or off < 0:
            self.bad(f"{w}.byteOffset", f"{off!r}; must be an integer >= 0")
            return None
        if off % size:
            self.bad(f"{w}.byteOffset", f"{off} is not a multiple of the component size {size}")
        arr = np.zeros((n, width), dtype=np.float64 if ct == 5126 else np.int64)
        vi = a.get("bufferView")
        if vi is not None:
            if "bufferView" in a and self.index(a, "bufferView", "bufferViews", w) is None:
                return None
            v = self.view_ok.get(vi)
            if v is None:
                return None
            stride = v.get("byteStride") or elem
            if stride < elem:
                self.bad(f"bufferViews[{vi}].byteStride", f"{stride} is less than {w}'s element size {elem}")
            if (v.get("byteOffset", 0) + off) % size:
                self.bad(w, f"starts at buffer byte {v.get('byteOffset', 0) + off}, not a multiple of its component "
                            f"size {size}")
            need = off + stride * (n - 1) + elem
            if need > v["byteLength"]:
                self.bad(w, f"{n} elements of {elem} bytes (stride {stride}) from byte {off} need {need} bytes; "
                            f"bufferView {vi} has {v['byteLength']}")
                return None
            raw = self._view_bytes(vi)
            if raw is None:
                return None
            buf = np.frombuffer(raw, dtype=np.uint8)
            rows = np.lib.stride_tricks.as_strided(buf[off:], shape=(n, elem), strides=(stride, 1))
            if cols:
                parts = [rows[:, c * col_stride:c * col_stride + col_bytes] for c in range(cols[1])]
                rows = np.concatenate(parts, axis=1)
            arr = np.ascontiguousarray(rows).view(dtype).reshape(n, width).astype(arr.dtype)
        sparse = a.get("sparse")
        if sparse is not None:
            arr = self._sparse(sparse, f"{w}.sparse", n, dtype, width, arr)
        return arr

    def _sparse(self, s: Any, w: str, n: int, dtype: np.dtype, width: int, arr: np.ndarray) -> np.ndarray | None:
        if not isinstance(s, dict):
            self.bad(w, "must be an object")
            return None
        k = self.req(s, "count", w, int)
        ind, val = s.get("indices"), s.get("values")
        if not isinstance(ind, dict) or not isinstance(val, dict):
            self.bad(w, "needs indices and values objects")
            return None
        if k is None:
            return None
        if not 1 <= k <= n:
            self.bad(f"{w}.count", f"{k}; must be 1..{n} (the accessor's count)")
            return None
        ict = self.req(ind, "componentType", f"{w}.indices", int)
        if ict not in (5121, 5123, 5125):
            self.bad(f"{w}.indices.componentType", f"{ict!r}; must be an unsigned byte, short or int")
            return None
        got = []
        for part, dt, wid in ((ind, np.dtype(_COMPONENTS[ict]), 1), (val, dtype, width)):
            pw = f"{w}.{'indices' if part is ind else 'values'}"
            vi = self.index(part, "bufferView", "bufferViews", pw, required=True)
            if vi is None or vi not in self.view_ok:
                return None
            view = self.view_ok[vi]
            if "byteStride" in view or "target" in view:
                self.bad(f"bufferViews[{vi}]", f"used by {pw}: must have no byteStride or target")
            off = part.get("byteOffset", 0)
            need = off + k * wid * dt.itemsize
            if not _is_int(off) or need > view["byteLength"]:
                self.bad(pw, f"{k} x {wid * dt.itemsize} bytes from byte {off} run past bufferView {vi} "
                             f"({view['byteLength']} bytes)")
                return None
            raw = self._view_bytes(vi)
            if raw is None:
                return None
            got.append(np.frombuffer(raw, dtype=dt.newbyteorder("<"), count=k * wid, offset=off).reshape(k, wid))
        idx = got[0][:, 0].astype(np.int64)
        if np.any(np.diff(idx) <= 0):
            self.bad(f"{w}.indices", "must be strictly increasing")
        if idx.max() >= n:
            self.bad(f"{w}.indices", f"index {int(idx.max())} is past the accessor's count {n}")
            return None
        arr = arr.copy()
        arr[idx] = got[1]
        return arr

    def _meshes(self) -> None:
        self.n_targets: dict[int, int] = {}
        for m, mesh, w in self.objects("meshes"):
            prims = self.req(mesh, "primitives", w, list)
            if prims is None:
                continue
            if not prims:
                self.bad(f"{w}.primitives", "must have at least one primitive")
            counts = []
            for p, prim in enumerate(prims):
                pw = f"{w}.primitives[{p}]"
                if not isinstance(prim, dict):
                    self.bad(pw, "must be an object")
                    continue
                attrs = self.req(prim, "attributes", pw, dict)
                mode = prim.get("mode", 4)
                if not _is_int(mode) or not 0 <= mode <= 6:
                    self.bad(f"{pw}.mode", f"{mode!r}; must be 0..6")
                if "material" in prim:
                    self.index(prim, "material", "materials", pw)
                n_vertex = self._attributes(attrs or {}, f"{pw}.attributes")
                if "indices" in prim and (ia := self.index(prim, "indices", "accessors", pw)) is not None:
                    a = self.acc_ok.get(ia)
                    if a is not None and (a.get("type") != "SCALAR" or a.get("componentType") not in (5121, 5123,
                                                                                                        5125)):
                        self.bad(f"{pw}.indices", f"accessor {ia} must be a SCALAR of unsigned byte, short or int")
                    data = self.data.get(ia)
                    if data is not None and n_vertex is not None and len(data) and int(data.max()) >= n_vertex:
                        self.bad(f"{pw}.indices", f"accessor {ia} has index {int(data.max())}, past the vertex "
                                                  f"count {n_vertex}")
                    if a is not None and mode == 4 and a.get("count", 0) % 3:
                        self.bad(f"{pw}.indices", f"{a.get('count')} indices for triangles: not a multiple of 3")
                targets = prim.get("targets", [])
                if not isinstance(targets, list):
                    self.bad(f"{pw}.targets", "must be an array")
                    targets = []
                for t, tg in enumerate(targets):
                    if not isinstance(tg, dict):
                        self.bad(f"{pw}.targets[{t}]", "must be an object")
                        continue
                    tc = self._attributes(tg, f"{pw}.targets[{t}]", position_needs_minmax=True)
                    if tc is not None and n_vertex is not None and tc != n_vertex:
                        self.bad(f"{pw}.targets[{t}]", f"{tc} elements but the primitive has {n_vertex} vertices")
                counts.append(len(targets))
            if len(set(counts)) > 1:
                self.bad(f"{w}.primitives", f"morph target counts differ between primitives: {counts}; the spec "
                                            "asks the same number in every primitive of a mesh")
            n_t = counts[0] if counts else 0
            self.n_targets[m] = n_t
            weights = mesh.get("weights")
            if weights is not None and (not isinstance(weights, list) or len(weights) != n_t):
                self.bad(f"{w}.weights", f"{len(weights) if isinstance(weights, list) else weights!r} weights for "
                                         f"{n_t} morph targets")
            names = (mesh.get("extras") or {}).get("targetNames") if isinstance(mesh.get("extras"), dict) else None
            if isinstance(names, list) and len(names) != n_t:
                self.bad(f"{w}.extras.targetNames", f"{len(names)} names for {n_t} morph targets")

    def _attributes(self, attrs: dict, w: str, position_needs_minmax: bool = True) -> int | None:
        counts = {}
        for key, ai in attrs.items():
            if not _is_int(ai) or not 0 <= ai < len(self.items("accessors")):
                self.bad(f"{w}.{key}", f"{ai!r} is not an accessor index")
                continue
            a = self.acc_ok.get(ai)
            if a is None:
                continue
            counts[key] = a["count"]
            if key == "POSITION":
                if a.get("type") != "VEC3":
                    self.bad(f"{w}.POSITION", f"accessor {ai} must be VEC3")
                if position_needs_minmax and ("min" not in a or "max" not in a):
                    self.bad(f"{w}.POSITION", f"accessor {ai} needs min and max (spec: POSITION accessors)")
            if key == "NORMAL" and a.get("type") != "VEC3":
                self.bad(f"{w}.NORMAL", f"accessor {ai} must be VEC3")
        if len(set(counts.values())) > 1:
            self.bad(w, f"attribute counts differ: {counts}")
        return next(iter(counts.values()), None) if counts else None

    def _nodes(self) -> None:
        nodes = self.items("nodes")
        parent = [-1] * len(nodes)
        for i, node, w in self.objects("nodes"):
            for key, array in (("mesh", "meshes"), ("skin", "skins"), ("camera", "cameras")):
                if key in node:
                    self.index(node, key, array, w)
            if "matrix" in node and (not isinstance(node["matrix"], list) or len(node["matrix"]) != 16):
                self.bad(f"{w}.matrix", "must be 16 numbers")
            if "matrix" in node and any(k in node for k in ("translation", "rotation", "scale")):
                self.bad(w, "has both matrix and translation/rotation/scale")
            for key, size in (("translation", 3), ("rotation", 4), ("scale", 3)):
                if key in node and (not isinstance(node[key], list) or len(node[key]) != size):
                    self.bad(f"{w}.{key}", f"must be {size} numbers")
            for k, ch in enumerate(node.get("children", []) if isinstance(node.get("children"), list) else []):
                if not _is_int(ch) or not 0 <= ch < len(nodes):
                    self.bad(f"{w}.children[{k}]", f"{ch!r} is not a node index")
                elif parent[ch] != -1:
                    self.bad(f"{w}.children[{k}]", f"node {ch} already has parent {parent[ch]}")
                elif ch == i:
                    self.bad(f"{w}.children[{k}]", "a node cannot be its own child")
                else:
                    parent[ch] = i
        for i in range(len(nodes)):
            seen, j = set(), i
            while j != -1:
                if j in seen:
                    self.bad(f"nodes[{i}]", "its parents form a cycle")
                    break
                seen.add(j)
                j = parent[j]
        self.parent = parent

    def _skins(self) -> None:
        n_nodes = len(self.items("nodes"))
        joints_of: dict[int, int] = {}
        for s, skin, w in self.objects("skins"):
            joints = self.req(skin, "joints", w, list)
            if joints is None:
                continue
            if not joints:
                self.bad(f"{w}.joints", "must have at least one joint")
            for k, j in enumerate(joints):
                if not _is_int(j) or not 0 <= j < n_nodes:
                    self.bad(f"{w}.joints[{k}]", f"{j!r} is not a node index")
            if len(set(map(str, joints))) != len(joints):
                self.bad(f"{w}.joints", "a node appears twice")
            if "skeleton" in skin:
                self.index(skin, "skeleton", "nodes", w)
            if "inverseBindMatrices" in skin and (ai := self.index(skin, "inverseBindMatrices", "accessors", w)) \
                    is not None and (a := self.acc_ok.get(ai)) is not None:
                if a.get("type") != "MAT4" or a.get("componentType") != 5126:
                    self.bad(f"{w}.inverseBindMatrices", f"accessor {ai} must be MAT4 float")
                if a.get("count", 0) < len(joints):
                    self.bad(f"{w}.inverseBindMatrices", f"{a.get('count')} matrices for {len(joints)} joints")
            joints_of[s] = len(joints)
        meshes = self.items("meshes")
        for _, node, w in self.objects("nodes"):
            s, m = node.get("skin"), node.get("mesh")
            if not (_is_int(m) and 0 <= m < len(meshes) and isinstance(meshes[m], dict)):
                continue
            for p, prim in enumerate(meshes[m].get("primitives", [])):
                ai = prim.get("attributes", {}).get("JOINTS_0") if isinstance(prim, dict) else None
                if ai is None:
                    continue
                if s not in joints_of:
                    if "skin" not in node:
                        self.bad(w, f"mesh {m} primitive {p} has JOINTS_0 but the node has no skin")
                    continue
                data = self.data.get(ai) if _is_int(ai) else None
                if data is not None and int(data.max()) >= joints_of[s]:
                    self.bad(f"meshes[{m}].primitives[{p}].attributes.JOINTS_0",
                             f"joint {int(data.max())} but skin {s} has {joints_of[s]} joints")

    def _scenes(self) -> None:
        n_nodes = len(self.items("nodes"))
        for _, scene, w in self.objects("scenes"):
            for k, n in enumerate(scene.get("nodes", [])):
                if not _is_int(n) or not 0 <= n < n_nodes:
                    self.bad(f"{w}.nodes[{k}]", f"{n!r} is not a node index")
                elif self.parent[n] != -1:
                    self.bad(f"{w}.nodes[{k}]", f"node {n} is not a root (its parent is {self.parent[n]})")
        if "scene" in self.doc:
            self.index(self.doc, "scene", "scenes", "(top)")

    def _textures(self) -> None:
        for _, t, w in self.objects("textures"):
            self.index(t, "source", "images", w)
            self.index(t, "sampler", "samplers", w)
        for _, img, w in self.objects("images"):
            if ("uri" in img) == ("bufferView" in img):
                self.bad(w, "needs exactly one of uri and bufferView")
            if "bufferView" in img:
                self.index(img, "bufferView", "bufferViews", w)
                if img.get("mimeType") not in ("image/png", "image/jpeg"):
                    self.bad(f"{w}.mimeType", f"{img.get('mimeType')!r}; needed with a bufferView "
                                              "(image/png or image/jpeg)")
        for _, mat, w in self.objects("materials"):
            pbr = mat.get("pbrMetallicRoughness", {})
            refs = [(pbr, "baseColorTexture"), (pbr, "metallicRoughnessTexture"), (mat, "normalTexture"),
                    (mat, "occlusionTexture"), (mat, "emissiveTexture")]
            for obj, key in refs:
                info = obj.get(key) if isinstance(obj, dict) else None
                if isinstance(info, dict):
                    self.index(info, "index", "textures", f"{w}.{key}", required=True)
            mode = mat.get("alphaMode", "OPAQUE")
            if mode not in ("OPAQUE", "MASK", "BLEND"):
                self.bad(f"{w}.alphaMode", f"{mode!r}; must be OPAQUE, MASK or BLEND")

    # -- VRM ---------------------------------------------------------------------------------
    def _node_ref(self, v: Any, w: str, allow_minus_one: bool = False) -> None:
        n = len(self.items("nodes"))
        if allow_minus_one and v == -1:
            return
        if not _is_int(v) or not 0 <= v < n:
            self.bad(w, f"{v!r} is not a node index ({n} nodes)")

    def _vrm0(self) -> None:
        ext = (self.doc.get("extensions") or {}).get("VRM") if isinstance(self.doc.get("extensions"), dict) else None
        if not isinstance(ext, dict):
            return
        w = "extensions.VRM"
        for k, b in enumerate((ext.get("humanoid") or {}).get("humanBones", [])):
            if isinstance(b, dict):
                self._node_ref(b.get("node"), f"{w}.humanoid.humanBones[{k}].node")
        fp = ext.get("firstPerson") or {}
        if "firstPersonBone" in fp:
            self._node_ref(fp["firstPersonBone"], f"{w}.firstPerson.firstPersonBone", allow_minus_one=True)
        n_meshes = len(self.items("meshes"))
        for k, a in enumerate(fp.get("meshAnnotations", [])):
            m = a.get("mesh") if isinstance(a, dict) else None
            if not _is_int(m) or not 0 <= m < n_meshes:
                self.bad(f"{w}.firstPerson.meshAnnotations[{k}].mesh", f"{m!r} is not a mesh index")
        groups = (ext.get("blendShapeMaster") or {}).get("blendShapeGroups", [])
        for g, group in enumerate(groups if isinstance(groups, list) else []):
            for b, bind in enumerate(group.get("binds", []) if isinstance(group, dict) else []):
                bw = f"{w}.blendShapeMaster.blendShapeGroups[{g}].binds[{b}]"
                m, i = bind.get("mesh"), bind.get("index")
                if not _is_int(m) or not 0 <= m < n_meshes:
                    self.bad(f"{bw}.mesh", f"{m!r} is not a mesh index")
                elif not _is_int(i) or not 0 <= i < self.n_targets.get(m, 0):
                    self.bad(f"{bw}.index", f"{i!r}: mesh {m} has {self.n_targets.get(m, 0)} morph targets")
                wt = bind.get("weight", 100)
                if not isinstance(wt, (int, float)) or not 0 <= wt <= 100:
                    self.bad(f"{bw}.weight", f"{wt!r}; VRM 0.x bind weights are 0..100")
        sec = ext.get("secondaryAnimation") or {}
        for g, group in enumerate(sec.get("boneGroups", [])):
            for k, b in enumerate(group.get("bones", [])):
                self._node_ref(b, f"{w}.secondaryAnimation.boneGroups[{g}].bones[{k}]")
            if "center" in group:
                self._node_ref(group["center"], f"{w}.secondaryAnimation.boneGroups[{g}].center", True)
            n_col = len(sec.get("colliderGroups", []))
            for k, c in enumerate(group.get("colliderGroups", [])):
                if not _is_int(c) or not 0 <= c < n_col:
                    self.bad(f"{w}.secondaryAnimation.boneGroups[{g}].colliderGroups[{k}]",
                             f"{c!r} is not a collider group index ({n_col})")
        for g, group in enumerate(sec.get("colliderGroups", [])):
            self._node_ref(group.get("node"), f"{w}.secondaryAnimation.colliderGroups[{g}].node")
        n_tex = len(self.items("textures"))
        for k, prop in enumerate(ext.get("materialProperties", [])):
            for name, t in (prop.get("textureProperties") or {}).items():
                if not _is_int(t) or not 0 <= t < n_tex:
                    self.bad(f"{w}.materialProperties[{k}].textureProperties.{name}", f"{t!r} is not a texture index")

    def _vrm1(self) -> None:
        exts = self.doc.get("extensions") if isinstance(self.doc.get("extensions"), dict) else {}
        ext = exts.get("VRMC_vrm")
        if not isinstance(ext, dict):
            return
        w = "extensions.VRMC_vrm"
        for key in ("specVersion", "meta", "humanoid"):
            if key not in ext:
                self.bad(f"{w}.{key}", "missing (required)")
        meta = ext.get("meta") or {}
        for key in ("name", "authors", "licenseUrl"):
            if isinstance(meta, dict) and key not in meta:
                self.bad(f"{w}.meta.{key}", "missing (required)")
        for b, v in ((ext.get("humanoid") or {}).get("humanBones") or {}).items():
            self._node_ref(v.get("node") if isinstance(v, dict) else None, f"{w}.humanoid.humanBones.{b}.node")
        nodes = self.items("nodes")
        for k, a in enumerate((ext.get("firstPerson") or {}).get("meshAnnotations", [])):
            self._node_ref(a.get("node") if isinstance(a, dict) else None, f"{w}.firstPerson.meshAnnotations[{k}]"
                                                                           ".node")
        for group in ("preset", "custom"):
            for name, e in ((ext.get("expressions") or {}).get(group) or {}).items():
                for b, bind in enumerate(e.get("morphTargetBinds", []) if isinstance(e, dict) else []):
                    bw = f"{w}.expressions.{group}.{name}.morphTargetBinds[{b}]"
                    node, i = bind.get("node"), bind.get("index")
                    if not _is_int(node) or not 0 <= node < len(nodes):
                        self.bad(f"{bw}.node", f"{node!r} is not a node index")
                        continue
                    m = nodes[node].get("mesh") if isinstance(nodes[node], dict) else None
                    if not _is_int(m):
                        self.bad(f"{bw}.node", f"node {node} has no mesh")
                    elif not _is_int(i) or not 0 <= i < self.n_targets.get(m, 0):
                        self.bad(f"{bw}.index", f"{i!r}: mesh {m} has {self.n_targets.get(m, 0)} morph targets")
                    wt = bind.get("weight", 1.0)
                    if not isinstance(wt, (int, float)) or not 0 <= wt <= 1:
                        self.bad(f"{bw}.weight", f"{wt!r}; VRM 1.0 bind weights are 0..1")


def _normalize(values: np.ndarray, ct: int) -> np.ndarray:
    """Normalized integer components as floats (spec 3.11: max(c / (2^(b-1) - 1), -1) for signed)."""
    info = np.iinfo(_COMPONENTS[ct])
    if info.min < 0:
        return np.maximum(values / info.max, -1.0)
    return values / info.max
