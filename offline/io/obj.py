"""Wavefront OBJ reader: positions, triangulated faces and material groups.

The ICT-FaceKit rig is 56 OBJ files of 2.5 MB each, so the reader works on
the whole file as one byte array with NumPy instead of a per-line Python
loop: lines are found and classified by their keyword with array operations,
the number fields of each kind (``v``, ``vt``, ``vn``, ``f``) are gathered
into one buffer and converted in one call. When that fast path meets
anything it cannot convert, a plain per-line pass over the same lines finds
the first bad line and raises :class:`ObjError` naming the file and line.

Supported statements: ``v x y z [w] [r g b]`` (``w`` is ignored, an optional
colour is kept), ``vt``, ``vn``, ``f`` with corners ``v``, ``v/vt``,
``v//vn``, ``v/vt/vn`` and negative (relative) indices, polygons of 3 or more
corners (fan-triangulated, winding kept), ``usemtl``, ``mtllib``; ``g``,
``o``, ``s``, ``l``, ``p`` and other statements are ignored, as are comments
(also at the end of a line), blank lines and CRLF line ends. Texture and
normal indices of face corners are not used: a character takes its normals
from the geometry and has no textures.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file

__all__ = ["ObjError", "ObjMesh", "read_obj", "read_vertices_only"]


class ObjError(InputFileError):
    """An OBJ file cannot be read; the message names the file and, where known, the line."""

    def __init__(self, path: str | os.PathLike, line: int | None, problem: str) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True, eq=False)
class ObjMesh:
    """A triangulated OBJ mesh.

    Attributes
    ----------
    vertices : ndarray of shape (n_vertices, 3), float64, file units
    triangles : ndarray of shape (n_triangles, 3), int64, 0-based, winding as in the file
    triangle_material : ndarray of shape (n_triangles,), int64, index into ``material_names``
    material_names : tuple of str, in order of first use; "default" for faces before any ``usemtl``
    mtllib : str or None, the first ``mtllib`` file name as written
    source : str, the file read
    vertex_colors : ndarray of shape (n_vertices, 3), float64, or None when the file has none
    texcoords : ndarray of shape (n_texcoords, 2), float64
    normals : ndarray of shape (n_normals, 3), float64
    n_faces : int, polygons before triangulation
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_material: np.ndarray
    material_names: tuple[str, ...]
    mtllib: str | None
    source: str
    vertex_colors: np.ndarray | None = None
    texcoords: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    n_faces: int = 0


# -- scanning --------------------------------------------------------------
_WS = np.zeros(257, dtype=bool)
_WS[[9, 10, 11, 12, 13, 32]] = True
_V, _VT, _VN, _F, _OTHER = 1, 2, 3, 4, 0


@dataclass(frozen=True)
class _Scan:
    """Lines of one file: where each keyword ends and each line ends (byte offsets)."""

    path: str
    buf: np.ndarray  # uint8, the file with "\n" line ends, plus one "\n" sentinel
    kw_start: np.ndarray  # (n_lines,) int64, first non-blank byte (== end for blank lines)
    kw_end: np.ndarray  # (n_lines,) int64, first blank byte after the keyword
    end: np.ndarray  # (n_lines,) int64, offset of the line's "\n"
    code: np.ndarray  # (n_lines,) int8, _V/_VT/_VN/_F/_OTHER

    def text(self, line: int, start=None) -> str:
        a = self.kw_start[line] if start is None else start[line]
        return self.buf[a : self.end[line]].tobytes().decode("utf-8", "replace").strip()

    def keyword(self, line: int) -> str:
        return self.buf[self.kw_start[line] : self.kw_end[line]].tobytes().decode("utf-8", "replace")


def _scan(path: str | os.PathLike) -> _Scan:
    path = str(regular_file(path, "OBJ file"))
    data = Path(path).read_bytes()
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    buf = np.frombuffer(data + b"\n", dtype=np.uint8)
    n = len(buf) - 1  # the sentinel "\n" closes a last line without one
    newlines = np.flatnonzero(buf == 10)
    starts = np.concatenate(([0], newlines[:-1] + 1))
    ends = newlines
    if n and data.endswith(b"\n"):  # no phantom empty line after the final "\n"
        starts, ends = starts[:-1], ends[:-1]
    blank = _WS[buf]
    nonblank = np.append(np.flatnonzero(~blank), len(buf))
    blanks = np.append(np.flatnonzero(blank), len(buf))
    kw_start = np.minimum(nonblank[np.searchsorted(nonblank, starts)], ends)
    kw_end = np.minimum(blanks[np.searchsorted(blanks, kw_start)], ends)
    length = kw_end - kw_start
    b0 = buf[np.minimum(kw_start, n)]
    b1 = buf[np.minimum(kw_start + 1, n)]
    code = np.zeros(len(starts), dtype=np.int8)
    code[(length == 1) & (b0 == ord("v"))] = _V
    code[(length == 2) & (b0 == ord("v")) & (b1 == ord("t"))] = _VT
    code[(length == 2) & (b0 == ord("v")) & (b1 == ord("n"))] = _VN
    code[(length == 1) & (b0 == ord("f"))] = _F
    return _Scan(path, buf, kw_start, kw_end, ends, code)


def _gather(scan: _Scan, lines: np.ndarray):
    """Bytes after the keyword of ``lines``, each ended by "\\n", comments blanked.

    Returns the bytes, the start offset of every token, and the position in
    ``lines`` each token belongs to.
    """
    starts, ends = scan.kw_end[lines], scan.end[lines]
    lengths = ends - starts + 1  # include the "\n"
    first = np.cumsum(lengths) - lengths
    idx = np.repeat(starts - first, lengths) + np.arange(int(lengths.sum()))
    seg = scan.buf[idx].copy()
    line_of_byte = np.repeat(np.arange(len(lines)), lengths)
    hashes = seg == ord("#")
    if hashes.any():  # blank "# ..." to the end of its line
        count = np.cumsum(hashes)
        before_line = (count - hashes)[first]
        seg[(count - before_line[line_of_byte] > 0) & (seg != 10)] = 32
    blank = _WS[seg]
    tok_start = np.flatnonzero(~blank & np.concatenate(([True], blank[:-1])))
    return seg, tok_start, line_of_byte[tok_start]


def _floats(scan: _Scan, code: int, name: str, widths: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the ``code`` lines, (n, widest field count) float64, NaN padded, and their field counts."""
    lines = np.flatnonzero(scan.code == code)
    if len(lines) == 0:
        return np.zeros((0, min(widths))), np.zeros(0, dtype=np.int64)
    seg, _, tok_line = _gather(scan, lines)
    counts = np.bincount(tok_line, minlength=len(lines))
    try:
        values = np.array(seg.tobytes().split(), dtype=np.float64)
    except ValueError:
        values = None
    if values is None or not np.isin(counts, widths).all():
        _slow_float_lines(scan, lines, name, widths)  # raises, naming the line
        raise ObjError(scan.path, None, f"unreadable '{name}' lines")  # pragma: no cover
    finite = np.isfinite(values)
    if not finite.all():
        line = int(lines[tok_line[np.argmin(finite)]])
        raise ObjError(scan.path, line + 1, f"non-finite number in '{scan.text(line)}'")
    if np.all(counts == counts[0]):
        return values.reshape(len(lines), int(counts[0])), counts
    rows = np.full((len(lines), int(counts.max())), np.nan)
    col = np.arange(len(values)) - np.repeat(np.cumsum(counts) - counts, counts)
    rows[np.repeat(np.arange(len(lines)), counts), col] = values
    return rows, counts


def _slow_float_lines(scan: _Scan, lines: np.ndarray, name: str, widths: tuple[int, ...]) -> None:
    """The obvious per-line check, run only to name the line the fast path stumbled on."""
    for line in lines:
        fields = scan.text(line, scan.kw_end).split("#", 1)[0].split()
        if len(fields) not in widths:
            raise ObjError(
                scan.path,
                int(line) + 1,
                f"'{name}' needs {' or '.join(map(str, widths))} numbers, got {len(fields)}: "
                f"'{scan.text(line)}'",
            )
        for f in fields:
            try:
                float(f)
            except ValueError:
                raise ObjError(scan.path, int(line) + 1, f"not a number: {f!r} in '{scan.text(line)}'") from None


def _vertex_rows(scan: _Scan) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (n, 3) and colours (n, 3) or None of the 'v' lines (x y z [w] [r g b])."""
    rows, counts = _floats(scan, _V, "v", (3, 4, 6, 7))
    if len(rows) == 0:
        raise ObjError(scan.path, None, "no vertices ('v' lines) in the file")
    too_big = np.abs(rows[:, :3]) > np.finfo(np.float32).max
    if too_big.any():  # a character stores float32 positions
        line = int(np.flatnonzero(scan.code == _V)[np.argmax(too_big.any(axis=1))])
        raise ObjError(scan.path, line + 1, f"coordinate beyond the float32 range in '{scan.text(line)}'")
    colors = None
    with6, with7 = counts == 6, counts == 7
    if with6.any() or with7.any():
        colors = np.ones((len(rows), 3))  # vertices without a colour are white
        colors[with6] = rows[with6, 3:6]
        if with7.any():
            colors[with7] = rows[with7, 4:7]
    return np.ascontiguousarray(rows[:, :3]), colors


def read_vertices_only(path: str | os.PathLike, expected: int | None = None) -> np.ndarray:
    """Vertex positions of an OBJ file, skipping everything else (for shapes sharing a topology).

    Parameters
    ----------
    path : path of the OBJ file
    expected : int, optional; the vertex count the file must have (the neutral's)

    Returns
    -------
    vertices : ndarray of shape (n_vertices, 3), float64, file units

    Raises
    ------
    ObjError
        garbled or non-finite numbers (file and line), no vertices, or a count other than ``expected``.
    """
    scan = _scan(path)
    vertices, _ = _vertex_rows(scan)
    if expected is not None and len(vertices) != expected:
        raise ObjError(scan.path, None, f"has {len(vertices)} vertices, expected {expected}")
    return vertices


def read_obj(path: str | os.PathLike) -> ObjMesh:
    """Read an OBJ file and fan-triangulate its polygons.

    Parameters
    ----------
    path : path of the OBJ file

    Returns
    -------
    ObjMesh

    Raises
    ------
    FileNotFoundError
        the file does not exist.
    ObjError
        garbled numbers, non-finite coordinates, a face with fewer than 3
        corners, an index of 0 or out of range (each naming file and line),
        or a file with no vertices.
    """
    scan = _scan(path)
    vertices, colors = _vertex_rows(scan)
    texcoords, _ = _floats(scan, _VT, "vt", (1, 2, 3))
    normals, _ = _floats(scan, _VN, "vn", (3,))
    face_lines = np.flatnonzero(scan.code == _F)
    corners, corner_count = _face_corners(scan, face_lines, len(vertices))
    triangles = _fan(corners, corner_count)
    materials, mtllib = _material_lines(scan)
    names: list[str] = []
    ids = np.zeros(len(materials), dtype=np.int64)
    for i, (_, name) in enumerate(materials):
        if name not in names:
            names.append(name)
        ids[i] = names.index(name)
    at = np.searchsorted(np.array([ln for ln, _ in materials], dtype=np.int64), face_lines) - 1
    face_material = np.where(at >= 0, ids[np.maximum(at, 0)] if len(ids) else 0, -1)
    if (face_material < 0).any():  # faces before the first usemtl
        names.insert(0, "default")
        face_material = face_material + 1
    return ObjMesh(
        vertices=vertices,
        triangles=triangles,
        triangle_material=np.repeat(face_material, corner_count - 2),
        material_names=tuple(names),
        mtllib=mtllib,
        source=scan.path,
        vertex_colors=colors,
        texcoords=_uv(texcoords),
        normals=normals,
        n_faces=len(face_lines),
    )


def _uv(rows: np.ndarray) -> np.ndarray:
    """(n, 2) u, v from 'vt' rows of 1 to 3 numbers (a missing v is 0)."""
    uv = np.zeros((len(rows), 2))
    uv[:, : min(2, rows.shape[1])] = rows[:, :2]
    return np.nan_to_num(uv)


def _material_lines(scan: _Scan) -> tuple[list[tuple[int, str]], str | None]:
    """(line, name) of every ``usemtl`` in order, and the first ``mtllib`` name."""
    candidates = np.flatnonzero((scan.code == _OTHER) & (scan.kw_end - scan.kw_start == 6))
    used, mtllib = [], None
    for line in candidates:
        keyword = scan.keyword(line)
        rest = scan.text(line, scan.kw_end).split("#", 1)[0].strip()
        if keyword == "usemtl":
            if not rest:
                raise ObjError(scan.path, int(line) + 1, "'usemtl' without a material name")
            used.append((int(line), rest))
        elif keyword == "mtllib" and mtllib is None and rest:
            mtllib = rest
    return used, mtllib


def _face_corners(scan: _Scan, lines: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """0-based vertex index of every corner (all faces concatenated) and the corner count per face."""
    if len(lines) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    seg, tok_start, tok_line = _gather(scan, lines)
    counts = np.bincount(tok_line, minlength=len(lines))
    # keep the vertex index of each "v/vt/vn" corner: blank from the first "/" to the token's end
    slash = seg == ord("/")
    seen = np.cumsum(slash)
    is_start = np.zeros(len(seg), dtype=bool)
    is_start[tok_start] = True
    token_of_byte = np.cumsum(is_start) - 1
    before = seen[tok_start] - slash[tok_start]
    after = (seen - before[np.maximum(token_of_byte, 0)] > 0) & (token_of_byte >= 0) & ~_WS[seg]
    seg[after] = 32
    try:
        raw = np.array(seg.tobytes().split(), dtype=np.int64)
    except ValueError:
        raw = None
    if raw is None or len(raw) != len(tok_start) or (counts < 3).any() or (raw == 0).any():
        _slow_face_lines(scan, lines)
        raise ObjError(scan.path, None, "unreadable 'f' lines")  # pragma: no cover
    # a negative index counts back from the last vertex defined before the face
    defined = np.cumsum(scan.code == _V)[lines]
    corner_defined = np.repeat(defined, counts)
    index = np.where(raw > 0, raw - 1, corner_defined + raw)
    bad = (index < 0) | (index >= np.where(raw > 0, n_vertices, corner_defined))
    if bad.any():
        k = int(np.argmax(bad))
        line = int(lines[tok_line[k]])
        limit = n_vertices if raw[k] > 0 else int(corner_defined[k])
        raise ObjError(
            scan.path, line + 1, f"vertex index {int(raw[k])} out of range for {limit} vertices: '{scan.text(line)}'"
        )
    return index, counts


def _slow_face_lines(scan: _Scan, lines: np.ndarray) -> None:
    """Per-line check of 'f' lines, run only to name the first bad one."""
    for line in lines:
        corners = scan.text(line, scan.kw_end).split("#", 1)[0].split()
        if len(corners) < 3:
            raise ObjError(
                scan.path, int(line) + 1, f"a face needs at least 3 corners, got {len(corners)}: '{scan.text(line)}'"
            )
        for corner in corners:
            try:
                value = int(corner.split("/", 1)[0])
            except ValueError:
                value = None
            if value is None or value == 0:
                raise ObjError(scan.path, int(line) + 1, f"bad face corner {corner!r} in '{scan.text(line)}'")


def _fan(corners: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons: corners (c0, c_j, c_j+1) for j = 1 .. k-2, winding kept."""
    n_tri = counts - 2
    first = np.cumsum(counts) - counts
    tri_face_first = np.repeat(first, n_tri)
    j = np.arange(int(n_tri.sum())) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri) + 1
    return np.stack(
        [corners[tri_face_first], corners[tri_face_first + j], corners[tri_face_first + j + 1]], axis=1
    ).astype(np.int64)
