"""A structural validity check of a glTF 2.0 / GLB / VRM file, written from the glTF 2.0 specification.

``check_gltf(path)`` returns a list of problems, each "where: what" (empty when
the file is sound). It reads the file itself (no glTF library), so a problem
it reports is one of the file, not of a reader. What it checks:

* the file and every buffer and image URI under the rules of :mod:`.gltf_files`,
  the importer's own: regular files only, inside the glTF's folder, sizes
  checked before reading, ``data:`` URIs bounded.
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
  increasing and below count; POSITION accessors (attributes and morph
  targets) have min and max, and any min/max given equal the data (float32)
  (:mod:`.gltf_check_accessors`).
* primitives: attribute counts equal, index values below the vertex count,
  indices a SCALAR of unsigned type; the same number of morph targets in every
  primitive of a mesh (and ``weights`` of that length).
* nodes: children, mesh, skin in range, no node with two parents, no cycle;
  skin joints are nodes, inverseBindMatrices a MAT4 float with a matrix per
  joint; JOINTS_0 values below the skin's joint count.
* scenes, textures (source, sampler), images (bufferView or uri, mimeType with
  a bufferView), material texture references in range.
* VRM 0.x and 1.0 references (:mod:`.gltf_check_vrm`).

The check never raises on what a file holds: a value of the wrong JSON type is
a problem naming its path (:mod:`.gltf_check_walk`). Its cost is bounded by the
file: the node walk is iterative and linear, the accessors' decoding has its
budgets (:mod:`.gltf_check_accessors`), and at most :data:`MAX_PROBLEMS` are
listed.
"""

from __future__ import annotations

import io
import json
import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from facepuppet.offline.io.gltf.read_materials import MAX_TEXTURE_SIDE, MAX_TEXTURE_TEXELS, image_size
from facepuppet.offline.io.gltf.structure_limits import structure_problems
from facepuppet.offline.io.gltf_check_accessors import AccessorCheck
from facepuppet.offline.io.gltf_check_vrm import check_vrm0, check_vrm1
from facepuppet.offline.io.gltf_check_walk import JsonWalk, is_int, is_number, show
from facepuppet.offline.io.gltf_files import GltfError, open_image_uri, read_buffer_uri, read_gltf_bytes

__all__ = ["check_gltf", "check_gltf_bytes", "MAX_PROBLEMS"]

GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
#: The most problems listed: a file with more is broken through and through, and listing a million lines helps no one.
MAX_PROBLEMS = 1000


def check_gltf(path: str | os.PathLike) -> list[str]:
    """Problems of the glTF / GLB / VRM file at ``path`` (see the module doc); [] when none.

    FileNotFoundError when it is missing; a file that is not a regular file, or too large, is a problem."""
    path = Path(path)
    try:
        data = read_gltf_bytes(path)
    except GltfError as exc:
        return [f"{exc.where or 'file'}: {exc.problem}"]
    return _check(data, path)


def check_gltf_bytes(data: bytes, base: Path | None = None, name: str = "file") -> list[str]:
    """Problems of glTF / GLB bytes; ``base`` is the folder of the file ``name`` (its external buffers and images
    are read from there; without it, only ``data:`` URIs are)."""
    return _check(data, None if base is None else Path(base) / name)


def _check(data: bytes, path: Path | None) -> list[str]:
    c = _Checker(path)
    try:
        c.run(data)
    except _Stop:
        pass
    return c.problems


class _Stop(Exception):
    pass


class _Checker(JsonWalk):
    def __init__(self, path: Path | None) -> None:
        super().__init__()
        self.path = path
        self.buffers: dict[int, bytes] = {}
        self.acc = AccessorCheck(self, self.buffers)
        self.n_targets: dict[int, int] = {}
        self.parent: list[int] = []

    def bad(self, where: str, what: str) -> None:
        super().bad(where, what)
        if len(self.problems) > MAX_PROBLEMS:
            self.problems[MAX_PROBLEMS:] = [f"(more problems not listed: the first {MAX_PROBLEMS} are)"]
            raise _Stop

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
            doc = json.loads(js.decode("utf-8"), parse_constant=_NotJson)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self.stop("JSON", f"not UTF-8 JSON ({str(exc)[:100]})")
        except RecursionError:
            self.stop("JSON", "nested too deeply to be read")
        if not isinstance(doc, dict):
            self.stop("JSON", "the top level is not an object")
        not_json = list(_not_json_values(doc))
        for where, name in not_json:
            self.bad(where, f"{name} is not a JSON number (RFC 8259 has no NaN or Infinity)")
        if not_json:
            raise _Stop
        self.doc = doc
        beyond = list(structure_problems(doc))  # the importer's limits: checked first, so that the walk stays short
        for where, what in beyond:
            self.bad(where, f"{what} (beyond what facepuppet imports)")
        if beyond:
            raise _Stop
        self._asset()
        self._buffers(bin_chunk, glb=data[:4] == b"glTF")
        self.acc.check_views()
        self.acc.check_accessors()
        self._meshes()
        self._nodes()
        self._skins()
        self._scenes()
        self._textures()
        check_vrm0(self, self.n_targets)
        check_vrm1(self, self.n_targets)

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

    # -- sections ---------------------------------------------------------------------------
    def _asset(self) -> None:
        asset = self.doc.get("asset")
        if not isinstance(asset, dict):
            self.bad("asset", "missing (required)" if asset is None else f"{show(asset)}: must be an object")
            return
        v = self.req(asset, "version", "asset", str)
        if v is not None and not v.startswith("2."):
            self.bad("asset.version", f"{show(v)}; this is a glTF 2.0 check")

    def _buffers(self, bin_chunk: bytes | None, glb: bool) -> None:
        for i, b, w in self.objects("buffers"):
            n = self.req(b, "byteLength", w, int)
            if n is not None and n < 1:
                self.bad(f"{w}.byteLength", f"{n}; must be >= 1")
                n = None
            if "uri" not in b:
                if not (glb and i == 0):
                    self.bad(w, "no uri, and only the first buffer of a GLB may use the BIN chunk")
                elif bin_chunk is None:
                    self.bad(w, "refers to the GLB BIN chunk, but the file has none")
                elif n is not None and not n <= len(bin_chunk) <= n + 3:
                    self.bad(f"{w}.byteLength", f"{n} but the BIN chunk holds {len(bin_chunk)} bytes "
                                                "(it may be at most 3 bytes of padding longer)")
                if bin_chunk is not None and n is not None and len(bin_chunk) >= n:
                    self.buffers[i] = bin_chunk
                continue
            uri = self.value(b, "uri", str, w)
            if uri is None or n is None or not (uri.startswith("data:") or self.path is not None):
                continue
            try:
                self.buffers[i], _ = read_buffer_uri(self.path or Path("file"), uri, w, n)
            except GltfError as exc:
                self.bad(exc.where, exc.problem)

    def _meshes(self) -> None:
        for m, mesh, w in self.objects("meshes"):
            prims = self.req(mesh, "primitives", w, list)
            if prims is None:
                continue
            if not prims:
                self.bad(f"{w}.primitives", "must have at least one primitive")
            counts = []
            for _, prim, pw in self.entries(prims, f"{w}.primitives"):
                attrs = self.req(prim, "attributes", pw, dict)
                mode = prim.get("mode", 4)
                if not is_int(mode) or not 0 <= mode <= 6:
                    self.bad(f"{pw}.mode", f"{show(mode)}; must be 0..6")
                if "material" in prim:
                    self.index(prim, "material", "materials", pw)
                n_vertex = self._attributes(attrs or {}, f"{pw}.attributes")
                if "indices" in prim and (ia := self.index(prim, "indices", "accessors", pw)) is not None:
                    self._indices(ia, pw, mode, n_vertex)
                targets = self.list_at(prim, "targets", pw)
                for _, tg, tw in self.entries(targets, f"{pw}.targets"):
                    tc = self._attributes(tg, tw, position_needs_minmax=True)
                    if tc is not None and n_vertex is not None and tc != n_vertex:
                        self.bad(tw, f"{tc} elements but the primitive has {n_vertex} vertices")
                counts.append(len(targets))
            if len(set(counts)) > 1:
                self.bad(f"{w}.primitives", f"morph target counts differ between primitives: {show(counts)}; the "
                                            "spec asks the same number in every primitive of a mesh")
            n_t = counts[0] if counts else 0
            self.n_targets[m] = n_t
            weights = mesh.get("weights")
            if weights is not None and (not isinstance(weights, list) or len(weights) != n_t):
                self.bad(f"{w}.weights", f"{len(weights) if isinstance(weights, list) else show(weights)} weights for "
                                         f"{n_t} morph targets")
            elif weights is not None and not all(map(is_number, weights)):
                self.bad(f"{w}.weights", "must be numbers")
            names = self.list_at(self.dict_at(mesh, "extras", w), "targetNames", f"{w}.extras")
            if names and len(names) != n_t:
                self.bad(f"{w}.extras.targetNames", f"{len(names)} names for {n_t} morph targets")

    def _indices(self, ia: int, pw: str, mode: Any, n_vertex: int | None) -> None:
        """Primitive ``pw``'s index accessor ``ia``: an unsigned SCALAR, values below ``n_vertex``, whole triangles."""
        a = self.acc.ok.get(ia)
        if a is None:
            return
        if a.get("type") != "SCALAR" or a.get("componentType") not in (5121, 5123, 5125):
            self.bad(f"{pw}.indices", f"accessor {ia} must be a SCALAR of unsigned byte, short or int")
        top = self.acc.top.get(ia)
        if top is not None and n_vertex is not None and top >= n_vertex:
            self.bad(f"{pw}.indices", f"accessor {ia} has index {int(top)}, past the vertex count {n_vertex}")
        if mode == 4 and a["count"] % 3:
            self.bad(f"{pw}.indices", f"{a['count']} indices for triangles: not a multiple of 3")

    def _attributes(self, attrs: dict, w: str, position_needs_minmax: bool = True) -> int | None:
        counts = {}
        for key, ai in attrs.items():
            if not is_int(ai) or not 0 <= ai < len(self.items("accessors")):
                self.bad(f"{w}.{key}", f"{show(ai)} is not an accessor index")
                continue
            a = self.acc.ok.get(ai)
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
            self.bad(w, f"attribute counts differ: {show(counts)}")
        return next(iter(counts.values()), None) if counts else None

    def _nodes(self) -> None:
        nodes = self.items("nodes")
        parent = [-1] * len(nodes)
        for i, node, w in self.objects("nodes"):
            for key, array in (("mesh", "meshes"), ("skin", "skins"), ("camera", "cameras")):
                if key in node:
                    self.index(node, key, array, w)
            if "matrix" in node and not _numbers(node["matrix"], 16):
                self.bad(f"{w}.matrix", "must be 16 numbers")
            if "matrix" in node and any(k in node for k in ("translation", "rotation", "scale")):
                self.bad(w, "has both matrix and translation/rotation/scale")
            for key, size in (("translation", 3), ("rotation", 4), ("scale", 3)):
                if key in node and not _numbers(node[key], size):
                    self.bad(f"{w}.{key}", f"must be {size} numbers")
            for k, ch in enumerate(self.list_at(node, "children", w)):
                if not is_int(ch) or not 0 <= ch < len(nodes):
                    self.bad(f"{w}.children[{k}]", f"{show(ch)} is not a node index")
                elif parent[ch] != -1:
                    self.bad(f"{w}.children[{k}]", f"node {ch} already has parent {parent[ch]}")
                elif ch == i:
                    self.bad(f"{w}.children[{k}]", "a node cannot be its own child")
                else:
                    parent[ch] = i
        for i in _in_cycles(parent):
            self.bad(f"nodes[{i}]", "its parents form a cycle")
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
                if not is_int(j) or not 0 <= j < n_nodes:
                    self.bad(f"{w}.joints[{k}]", f"{show(j)} is not a node index")
            ints = [j for j in joints if is_int(j)]
            if len(set(ints)) != len(ints):
                self.bad(f"{w}.joints", "a node appears twice")
            if "skeleton" in skin:
                self.index(skin, "skeleton", "nodes", w)
            if "inverseBindMatrices" in skin and (ai := self.index(skin, "inverseBindMatrices", "accessors", w)) \
                    is not None and (a := self.acc.ok.get(ai)) is not None:
                if a.get("type") != "MAT4" or a.get("componentType") != 5126:
                    self.bad(f"{w}.inverseBindMatrices", f"accessor {ai} must be MAT4 float")
                if a["count"] < len(joints):
                    self.bad(f"{w}.inverseBindMatrices", f"{a['count']} matrices for {len(joints)} joints")
            joints_of[s] = len(joints)
        meshes = self.items("meshes")
        for _, node, w in self.objects("nodes"):
            s, m = node.get("skin"), node.get("mesh")
            if not (is_int(m) and 0 <= m < len(meshes) and isinstance(meshes[m], dict)):
                continue
            prims = meshes[m].get("primitives")
            for p, prim in enumerate(prims if isinstance(prims, list) else []):
                attrs = prim.get("attributes") if isinstance(prim, dict) else None
                ai = attrs.get("JOINTS_0") if isinstance(attrs, dict) else None
                if ai is None:
                    continue
                if not (is_int(s) and s in joints_of):
                    if "skin" not in node:
                        self.bad(w, f"mesh {m} primitive {p} has JOINTS_0 but the node has no skin")
                    continue
                top = self.acc.top.get(ai) if is_int(ai) else None
                if top is not None and top >= joints_of[s]:
                    self.bad(f"meshes[{m}].primitives[{p}].attributes.JOINTS_0",
                             f"joint {int(top)} but skin {s} has {joints_of[s]} joints")

    def _scenes(self) -> None:
        n_nodes = len(self.items("nodes"))
        for _, scene, w in self.objects("scenes"):
            for k, n in enumerate(self.list_at(scene, "nodes", w)):
                if not is_int(n) or not 0 <= n < n_nodes:
                    self.bad(f"{w}.nodes[{k}]", f"{show(n)} is not a node index")
                elif self.parent[n] != -1:
                    self.bad(f"{w}.nodes[{k}]", f"node {n} is not a root (its parent is {self.parent[n]})")
        if "scene" in self.doc:
            self.index(self.doc, "scene", "scenes", "(top)")

    def _texture_budget(self, sizes: list[tuple[str, tuple[int, int] | None]]) -> None:
        """Each image's size (from its header; nothing is decoded) within the importer's texture limits."""
        total = 0
        for w, size in sizes:
            if size is None:
                self.bad(w, "not a PNG or JPEG image whose size its header gives")
                continue
            width, height = size
            if max(width, height) > MAX_TEXTURE_SIDE:
                self.bad(w, f"{width}x{height} texels: larger than {MAX_TEXTURE_SIDE}x{MAX_TEXTURE_SIDE} "
                            "(beyond what facepuppet imports)")
            total += width * height
            if total > MAX_TEXTURE_TEXELS:
                self.bad(w, f"{width}x{height} texels bring the images to {total} texels, more than "
                            f"{MAX_TEXTURE_TEXELS} (beyond what facepuppet imports)")
                return

    def _textures(self) -> None:
        sizes: list[tuple[str, tuple[int, int] | None]] = []
        for _, t, w in self.objects("textures"):
            self.index(t, "source", "images", w)
            self.index(t, "sampler", "samplers", w)
        for _, img, w in self.objects("images"):
            if ("uri" in img) == ("bufferView" in img):
                self.bad(w, "needs exactly one of uri and bufferView")
            if "bufferView" in img:
                self.index(img, "bufferView", "bufferViews", w)
                if img.get("mimeType") not in ("image/png", "image/jpeg"):
                    self.bad(f"{w}.mimeType", f"{show(img.get('mimeType'))}; needed with a bufferView "
                                              "(image/png or image/jpeg)")
            uri = self.value(img, "uri", str, w)
            if uri is not None and (uri.startswith("data:") or self.path is not None):
                try:
                    with open_image_uri(self.path or Path("file"), uri, f"{w}.uri").handle as handle:
                        sizes.append((w, image_size(handle)))
                except GltfError as exc:
                    self.bad(exc.where, exc.problem)
            elif "bufferView" in img and is_int(img["bufferView"]) and img["bufferView"] in self.acc.views:
                data = self.acc.view_bytes(img["bufferView"])
                if data is not None:
                    sizes.append((w, image_size(io.BytesIO(data))))
        self._texture_budget(sizes)
        for _, mat, w in self.objects("materials"):
            pbr = self.dict_at(mat, "pbrMetallicRoughness", w)
            refs = [(pbr, "baseColorTexture", f"{w}.pbrMetallicRoughness"),
                    (pbr, "metallicRoughnessTexture", f"{w}.pbrMetallicRoughness"), (mat, "normalTexture", w),
                    (mat, "occlusionTexture", w), (mat, "emissiveTexture", w)]
            for obj, key, ow in refs:
                info = self.value(obj, key, dict, ow)
                if info is not None:
                    self.index(info, "index", "textures", f"{ow}.{key}", required=True)
            mode = mat.get("alphaMode", "OPAQUE")
            if mode not in ("OPAQUE", "MASK", "BLEND"):
                self.bad(f"{w}.alphaMode", f"{show(mode)}; must be OPAQUE, MASK or BLEND")


class _NotJson(str):
    """A ``NaN``, ``Infinity`` or ``-Infinity`` that Python's JSON parser accepts and JSON does not have."""


def _not_json_values(doc: Any) -> Iterator[tuple[str, str]]:
    """(JSON path, the word) of each :class:`_NotJson` in ``doc``, walked without recursion."""
    stack = [("", doc)]
    while stack:
        where, value = stack.pop()
        if isinstance(value, _NotJson):
            yield where or "JSON", str(value)
        elif isinstance(value, dict):
            stack.extend((f"{where}.{k}" if where else str(k), v) for k, v in reversed(value.items()))
        elif isinstance(value, list):
            stack.extend((f"{where}[{i}]", v) for i, v in reversed(list(enumerate(value))))


def _numbers(v: Any, n: int) -> bool:
    """Whether ``v`` is an array of ``n`` finite numbers."""
    return isinstance(v, list) and len(v) == n and all(map(is_number, v))


def _in_cycles(parent: list[int]) -> list[int]:
    """The nodes whose chain of parents runs into a cycle, in order; one pass over the parent links (a chain
    60,000 nodes deep costs 60,000 steps, not 60,000²/2)."""
    state = [0] * len(parent)   # 0 not seen, 1 on the chain being followed, 2 done
    cyclic = [False] * len(parent)
    for i in range(len(parent)):
        chain, j = [], i
        while j != -1 and state[j] == 0:
            state[j] = 1
            chain.append(j)
            j = parent[j]
        hit = j != -1 and (state[j] == 1 or cyclic[j])
        for k in chain:
            state[k], cyclic[k] = 2, hit
    return [i for i in range(len(parent)) if cyclic[i]]
