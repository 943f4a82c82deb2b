"""The binary buffer of a written glTF: buffer views, accessors (dense, with min/max, or sparse).

Every view starts on a 4-byte boundary (the spec asks it of vertex
attributes; it costs nothing elsewhere). A sparse VEC3 accessor has no buffer
view of its own: zeros, with ``values`` at ``indices`` (uint16 when the count
allows, else uint32), and min/max over the zeros too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_COMPONENT = {np.dtype(np.float32): FLOAT, np.dtype(np.uint8): UBYTE, np.dtype(np.uint16): USHORT,
              np.dtype(np.uint32): UINT}


class Buffer:
    """The one binary buffer of the file: 4-byte aligned buffer views, accessors over them (glTF 2.0 §5.1, §5.11)."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = -self.size % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.size += pad
        v = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.parts.append(data)
        self.size += len(data)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, a: np.ndarray, target: int | None = ARRAY_BUFFER, minmax: bool = False,
                 normalized: bool = False) -> int:
        a = np.ascontiguousarray(a)
        width = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
        acc = {"bufferView": self.view(a.tobytes(), target), "componentType": _COMPONENT[a.dtype],
               "count": int(len(a)), "type": _TYPES[width]}
        if normalized:
            acc["normalized"] = True
        if minmax:
            flat = a.reshape(len(a), width)
            acc["min"], acc["max"] = _numbers(flat.min(axis=0)), _numbers(flat.max(axis=0))
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def sparse_vec3(self, count: int, idx: np.ndarray, values: np.ndarray) -> int:
        """A VEC3 float accessor of ``count`` zeros but ``values`` at ``idx`` (sorted); min/max included."""
        values = np.ascontiguousarray(values, dtype=np.float32)
        acc: dict[str, Any] = {"componentType": FLOAT, "count": int(count), "type": "VEC3"}
        if len(idx):
            lo, hi = values.min(axis=0), values.max(axis=0)
            if len(idx) < count:
                lo, hi = np.minimum(lo, 0), np.maximum(hi, 0)
            itype = np.uint16 if count <= 65535 else np.uint32
            acc["sparse"] = {"count": int(len(idx)),
                             "indices": {"bufferView": self.view(idx.astype(itype).tobytes()),
                                         "componentType": _COMPONENT[np.dtype(itype)]},
                             "values": {"bufferView": self.view(values.tobytes())}}
        else:
            lo = hi = np.zeros(3, np.float32)
        acc["min"], acc["max"] = _numbers(lo), _numbers(hi)
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.parts)


def _numbers(a: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=np.float32).tolist()]
