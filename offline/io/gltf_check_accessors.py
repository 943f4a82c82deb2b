"""The accessors of ``check-gltf``: buffer views in range, each accessor's data read and its min/max compared.

Buffer views must lie inside their buffer; an accessor's last element (with
its view's byteStride) inside its view; sparse indices and values inside
theirs, the indices strictly increasing and below count. The data is read in
the accessor's own component type, one accessor at a time, and only its
largest value is kept (index and JOINTS_0 ranges are checked from it), so the
check holds no more than one accessor's values at once.

Memory and time are bounded by the file: nothing is allocated before the
bytes it needs are known to be there; an accessor without a buffer view is
held to the importer's :data:`~.gltf_container.MAX_UNBACKED_VALUES`; and the
accessors decode at most :data:`DECODE_BUDGET_FACTOR` times the buffers'
bytes together (accessors side by side, or interleaved in one view, decode
each byte once; accessors laid over the same bytes thousands of times are a
bomb, not a model).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from facepuppet.offline.io.gltf_check_walk import JsonWalk, is_int, is_number, show
from facepuppet.offline.io.gltf_container import MAX_UNBACKED_VALUES

__all__ = ["AccessorCheck", "DECODE_BUDGET_FACTOR", "DECODE_BUDGET_FLOOR"]

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_COLUMNS = {"MAT2": (2, 2), "MAT3": (3, 3), "MAT4": (4, 4)}
#: The accessors together decode at most this many times the buffers' bytes (plus :data:`DECODE_BUDGET_FLOOR`):
#: accessors side by side, or interleaved in one view, decode each byte once.
DECODE_BUDGET_FACTOR = 4
DECODE_BUDGET_FLOOR = 64 << 20


class _View(NamedTuple):
    buffer: int
    offset: int
    length: int
    stride: int | None
    target: bool


class AccessorCheck:
    """The buffer views and accessors of the document ``walk`` checks, over the buffers' bytes read so far.

    After :meth:`check_views` and :meth:`check_accessors`: ``ok`` {index: JSON} of the accessors whose type,
    component type and count are sound; ``top`` {index: largest value} of those whose data could be read."""

    def __init__(self, walk: JsonWalk, buffers: dict[int, bytes]) -> None:
        self.walk, self.buffers = walk, buffers
        self.views: dict[int, _View] = {}
        self.ok: dict[int, dict] = {}
        self.top: dict[int, float] = {}
        self.decode_left = DECODE_BUDGET_FLOOR

    def check_views(self) -> None:
        """Buffer views: a buffer index, byteLength >= 1, byteOffset, byteStride 4..252 (x4), inside the buffer."""
        buffers = self.walk.items("buffers")
        for i, v, w in self.walk.objects("bufferViews"):
            b = self.walk.index(v, "buffer", "buffers", w, required=True)
            n = self.walk.req(v, "byteLength", w, int)
            off = v.get("byteOffset", 0)
            if not is_int(off) or off < 0:
                self.walk.bad(f"{w}.byteOffset", f"{show(off)}; must be an integer >= 0")
                continue
            stride = v.get("byteStride")
            if stride is not None and (not is_int(stride) or not 4 <= stride <= 252 or stride % 4):
                self.walk.bad(f"{w}.byteStride", f"{show(stride)}; must be 4..252 and a multiple of 4")
                continue
            if b is None or n is None:
                continue
            if n < 1:
                self.walk.bad(f"{w}.byteLength", f"{n}; must be >= 1")
                continue
            size = buffers[b].get("byteLength") if isinstance(buffers[b], dict) else None
            if is_int(size) and off + n > size:
                self.walk.bad(w, f"bytes {off}..{off + n} run past buffer {b}'s byteLength {size}")
                continue
            self.views[i] = _View(b, off, n, stride, "target" in v)

    def view_bytes(self, vi: int) -> memoryview | None:
        """The bytes of buffer view ``vi`` (no copy); None when its buffer could not be read in full."""
        v = self.views[vi]
        data = self.buffers.get(v.buffer)
        if data is None or v.offset + v.length > len(data):
            return None
        return memoryview(data)[v.offset:v.offset + v.length]

    def check_accessors(self) -> None:
        """Accessors: types, counts, their data read (within the budget) and min/max compared with it."""
        self.decode_left += DECODE_BUDGET_FACTOR * sum(len(b) for b in self.buffers.values())
        for i, a, w in self.walk.objects("accessors"):
            ct = self.walk.req(a, "componentType", w, int)
            n = self.walk.req(a, "count", w, int)
            t = self.walk.req(a, "type", w, str)
            normalized = self.walk.value(a, "normalized", bool, w, False)
            ok = True
            if ct is not None and ct not in _COMPONENTS:
                self.walk.bad(f"{w}.componentType", f"{ct} is not a glTF component type")
                ok = False
            if t is not None and t not in _WIDTH:
                self.walk.bad(f"{w}.type", f"{show(t)} is not SCALAR, VEC2..4 or MAT2..4")
                ok = False
            if n is not None and n < 1:
                self.walk.bad(f"{w}.count", f"{n}; must be >= 1")
                ok = False
            if not ok or None in (ct, n, t):
                continue
            arr = self._read(a, w, ct, n, t)
            self.ok[i] = a
            if arr is not None:
                top = arr.max()
                if np.isfinite(top):
                    self.top[i] = float(top)
            for key in ("min", "max"):
                if key not in a:
                    continue
                vals = a[key]
                if not (isinstance(vals, list) and len(vals) == _WIDTH[t] and all(map(is_number, vals))):
                    self.walk.bad(f"{w}.{key}", f"must be {_WIDTH[t]} numbers")
                    continue
                if arr is not None:
                    self._min_max(arr, key, vals, w, ct, normalized)

    def _min_max(self, arr: np.ndarray, key: str, vals: list, w: str, ct: int, normalized: bool) -> None:
        """A problem when the accessor's ``min`` / ``max`` (``key``) is not its data's."""
        with np.errstate(all="ignore"):  # data or bounds beyond float32 (or NaN) compare unequal, no warning
            got = (arr.min(axis=0) if key == "min" else arr.max(axis=0)).astype(np.float64)
            if normalized and ct != 5126:
                got = _normalize(got, ct)   # monotonic, so the min of the normalized values is the normalized min
            want = np.asarray(vals, dtype=np.float64)
            if ct == 5126:
                want, got = want.astype(np.float32), got.astype(np.float32)
            same = np.allclose(got, want, rtol=1e-6, atol=1e-7)
        if not same:
            self.walk.bad(f"{w}.{key}", f"{show(vals)} but the data's {key} is {show([float(x) for x in got])}")

    def _read(self, a: dict, w: str, ct: int, n: int, t: str) -> np.ndarray | None:
        """Accessor ``a``'s values (n, width), of its own component type; None when they cannot be read."""
        dtype = np.dtype(_COMPONENTS[ct]).newbyteorder("<")
        size = dtype.itemsize
        width = _WIDTH[t]
        cols = _COLUMNS.get(t)
        # matrix columns start on 4-byte boundaries (spec 3.6.2.4: MAT2/MAT3 of 1- and 2-byte components)
        col_bytes = cols[0] * size if cols else width * size
        col_stride = (col_bytes + 3) // 4 * 4 if cols else col_bytes
        elem = col_stride * (cols[1] if cols else 1)
        off = a.get("byteOffset", 0)
        if not is_int(off) or off < 0:
            self.walk.bad(f"{w}.byteOffset", f"{show(off)}; must be an integer >= 0")
            return None
        if off % size:
            self.walk.bad(f"{w}.byteOffset", f"{off} is not a multiple of the component size {size}")
        if "bufferView" not in a:
            if n * width > MAX_UNBACKED_VALUES:
                self.walk.bad(f"{w}.count", f"{n} {t} elements without a bufferView: more than the "
                                                 f"{MAX_UNBACKED_VALUES} values an accessor of zeros may have here")
                return None
            if not self._spend(n * width * size):
                return None
            arr = np.zeros((n, width), dtype=dtype)
        else:
            vi = self.walk.index(a, "bufferView", "bufferViews", w)
            if vi is None or vi not in self.views:
                return None
            v = self.views[vi]
            stride = v.stride or elem
            if stride < elem:
                self.walk.bad(f"bufferViews[{vi}].byteStride", f"{stride} is less than {w}'s element size {elem}")
                return None
            if (v.offset + off) % size:
                self.walk.bad(w, f"starts at buffer byte {v.offset + off}, not a multiple of its component size {size}")
            need = off + stride * (n - 1) + elem
            if need > v.length:
                self.walk.bad(w, f"{n} elements of {elem} bytes (stride {stride}) from byte {off} need {need} bytes; "
                                 f"bufferView {vi} has {v.length}")
                return None
            raw = self.view_bytes(vi)
            if raw is None or not self._spend(n * elem):
                return None
            buf = np.frombuffer(raw, dtype=np.uint8)
            rows = np.lib.stride_tricks.as_strided(buf[off:], shape=(n, elem), strides=(stride, 1), writeable=False)
            if cols:
                parts = [rows[:, c * col_stride:c * col_stride + col_bytes] for c in range(cols[1])]
                rows = np.concatenate(parts, axis=1)
            arr = np.array(rows, copy=True, order="C").view(dtype).reshape(n, width)
        sparse = a.get("sparse")
        if sparse is not None:
            arr = self._sparse(sparse, f"{w}.sparse", n, dtype, width, arr)
        return arr

    def _spend(self, n_bytes: int) -> bool:
        """Take ``n_bytes`` from the decoding budget; False (once a problem) when it is spent."""
        self.decode_left -= n_bytes
        if self.decode_left >= 0:
            return True
        self.walk.bad("accessors", f"decode more than {DECODE_BUDGET_FACTOR} times the buffers' bytes (they overlap "
                                   "over and over); the data of the rest is not checked")
        return False

    def _sparse(self, s: Any, w: str, n: int, dtype: np.dtype, width: int, arr: np.ndarray) -> np.ndarray | None:
        if not isinstance(s, dict):
            self.walk.bad(w, f"{show(s)}: must be an object")
            return None
        k = self.walk.req(s, "count", w, int)
        ind, val = s.get("indices"), s.get("values")
        if not isinstance(ind, dict) or not isinstance(val, dict):
            self.walk.bad(w, "needs indices and values objects")
            return None
        if k is None:
            return None
        if not 1 <= k <= n:
            self.walk.bad(f"{w}.count", f"{k}; must be 1..{n} (the accessor's count)")
            return None
        ict = self.walk.req(ind, "componentType", f"{w}.indices", int)
        if ict not in (5121, 5123, 5125):
            self.walk.bad(f"{w}.indices.componentType", f"{show(ict)}; must be an unsigned byte, short or int")
            return None
        got = []
        for part, dt, wid in ((ind, np.dtype(_COMPONENTS[ict]), 1), (val, dtype, width)):
            pw = f"{w}.{'indices' if part is ind else 'values'}"
            vi = self.walk.index(part, "bufferView", "bufferViews", pw, required=True)
            if vi is None or vi not in self.views:
                return None
            view = self.views[vi]
            if view.stride is not None or view.target:
                self.walk.bad(f"bufferViews[{vi}]", f"used by {pw}: must have no byteStride or target")
            off = part.get("byteOffset", 0)
            if not is_int(off) or off < 0:
                self.walk.bad(f"{pw}.byteOffset", f"{show(off)}; must be an integer >= 0")
                return None
            need = off + k * wid * dt.itemsize
            if need > view.length:
                self.walk.bad(pw, f"{k} x {wid * dt.itemsize} bytes from byte {off} run past bufferView {vi} "
                                  f"({view.length} bytes)")
                return None
            raw = self.view_bytes(vi)
            if raw is None:
                return None
            got.append(np.frombuffer(raw, dtype=dt.newbyteorder("<"), count=k * wid, offset=off).reshape(k, wid))
        idx = got[0][:, 0].astype(np.int64)
        if np.any(np.diff(idx) <= 0):
            self.walk.bad(f"{w}.indices", "must be strictly increasing")
        if idx.max() >= n:
            self.walk.bad(f"{w}.indices", f"index {int(idx.max())} is past the accessor's count {n}")
            return None
        arr = arr.copy()
        arr[idx] = got[1]
        return arr


def _normalize(values: np.ndarray, ct: int) -> np.ndarray:
    """Normalized integer components as floats (spec 3.11: max(c / (2^(b-1) - 1), -1) for signed)."""
    info = np.iinfo(_COMPONENTS[ct])
    if info.min < 0:
        return np.maximum(values / info.max, -1.0)
    return values / info.max
