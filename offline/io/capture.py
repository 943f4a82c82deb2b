"""Marker captures: read and write TRC, C3D and plain CSV as one :class:`Capture`.

Every reader returns markers as ``(n_frames, n_markers, 3)`` float32 with NaN
where a marker was occluded, the marker names, the frame rate and the units
read from the file. Short gaps (at most ``max_gap`` frames, inside the take)
are filled by linear interpolation; longer gaps and gaps at either end of the
take stay NaN and are listed in ``Capture.gaps``. A malformed file raises
:class:`CaptureError` naming the file and the line or field.

Plain CSV layout (our own, documented here)::

    # units: cm
    # rate: 60
    frame,time,ForeHead_M_x,ForeHead_M_y,ForeHead_M_z,...
    1,0.0,14.12,84.15,3.48,...

``frame`` and ``time`` are optional; empty cells are occluded samples. Units
come from the ``# units:`` line; the rate from ``# rate:`` or the time column.
"""

from __future__ import annotations

import csv
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from facepuppet.runtime.errors import InputFileError

UNITS = ("mm", "cm", "m")
DEFAULT_MAX_GAP = 10  # frames


class CaptureError(InputFileError):
    """A capture file cannot be read; names the file and the line or field."""

    def __init__(self, path: str | os.PathLike, where: str, problem: str) -> None:
        self.path, self.where, self.problem = str(path), where, problem
        super().__init__(f"{path}: {where}: {problem}")


class Gap(NamedTuple):
    """A run of occluded frames left unfilled: marker name, first frame (0-based), length."""

    marker: str
    start: int
    length: int


@dataclass(frozen=True, eq=False)
class Capture:
    """A marker take.

    Attributes
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float32, units; NaN = occluded
    names : tuple of n_markers str
    rate : float, frames per second
    units : str, "mm", "cm" or "m"
    source : str, the file it came from (or "")
    gaps : tuple of Gap, occlusions longer than the fill limit (still NaN)
    filled : int, samples filled by interpolation
    """

    markers: np.ndarray
    names: tuple[str, ...]
    rate: float
    units: str
    source: str = ""
    gaps: tuple[Gap, ...] = field(default=())
    filled: int = 0

    def __post_init__(self) -> None:
        where = self.source or "capture"
        with np.errstate(over="ignore"):  # a value beyond float32 becomes inf, refused below
            m = np.asarray(self.markers, dtype=np.float32)
        if m.ndim != 3 or m.shape[2] != 3 or m.shape[0] < 1 or m.shape[1] < 1:
            raise CaptureError(where, "markers", f"expected shape (n_frames, n_markers, 3), got {m.shape}")
        if len(self.names) != m.shape[1]:
            raise CaptureError(where, "names", f"expected {m.shape[1]} names, one per marker, got {len(self.names)}")
        if len(set(self.names)) != len(self.names):
            dup = sorted({n for n in self.names if list(self.names).count(n) > 1})
            raise CaptureError(where, "names", f"marker names must be distinct; repeated: {dup[:5]}")
        if np.isinf(m).any():
            frame, marker, _ = np.argwhere(np.isinf(m))[0]
            raise CaptureError(where, "markers", f"infinite or beyond float32 range (frame {frame}, marker "
                                                 f"{self.names[marker]!r})")
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise CaptureError(where, "rate", f"expected a positive frame rate, got {self.rate!r}")
        if self.units not in UNITS:
            raise CaptureError(where, "units", f"expected one of {UNITS}, got {self.units!r}")
        m.setflags(write=False)
        object.__setattr__(self, "markers", m)
        object.__setattr__(self, "names", tuple(self.names))

    @property
    def n_frames(self) -> int:
        return self.markers.shape[0]

    @property
    def n_markers(self) -> int:
        return self.markers.shape[1]


def fill_gaps(markers: np.ndarray, names: Sequence[str],
              max_gap: int = DEFAULT_MAX_GAP) -> tuple[np.ndarray, list[Gap], int]:
    """Linearly interpolate interior gaps of at most ``max_gap`` frames.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, NaN = occluded
    names : sequence of n_markers str
    max_gap : int, longest gap (frames) to fill

    Returns
    -------
    filled : ndarray of shape (n_frames, n_markers, 3), float32
    long_gaps : list of Gap left as NaN (too long, or touching the start/end)
    n_filled : int, number of (frame, marker) samples filled
    """
    with np.errstate(over="ignore"):  # beyond float32: inf, which Capture refuses naming the marker
        out = np.array(markers, dtype=np.float32, copy=True)
    missing = np.isnan(out).any(axis=2)
    out[missing] = np.nan
    gaps: list[Gap] = []
    n_filled = 0
    n = out.shape[0]
    for j in np.flatnonzero(missing.any(axis=0)):
        edges = np.diff(np.r_[0, missing[:, j].astype(np.int8), 0])
        for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            length = int(stop - start)
            if length > max_gap or start == 0 or stop == n:
                gaps.append(Gap(str(names[j]), int(start), length))
                continue
            a, b = out[start - 1, j], out[stop, j]
            t = (np.arange(1, length + 1, dtype=np.float32) / (length + 1))[:, None]
            with np.errstate(over="ignore", invalid="ignore"):  # absurd samples: inf, refused by Capture
                out[start:stop, j] = a + t * (b - a)
            n_filled += length
    return out, gaps, n_filled


def _finish(path, markers, names, rate, units, max_gap) -> Capture:
    for j, name in enumerate(names):
        if np.isnan(markers[:, j]).all():
            raise CaptureError(path, f"marker {name!r}", "has no sample in any frame (NaN-only marker)")
    filled, gaps, n = fill_gaps(markers, names, max_gap)
    return Capture(filled, tuple(names), float(rate), units, str(path), tuple(gaps), n)


def _units(path, where, text) -> str:
    u = text.strip().lower()
    if u in ("millimeters", "millimetres"):
        u = "mm"
    if u not in UNITS:
        raise CaptureError(path, where, f"units must be one of {UNITS}, found {text.strip()!r}")
    return u


def read_capture(path: str | os.PathLike, max_gap: int = DEFAULT_MAX_GAP) -> Capture:
    """Read a ``.trc``, ``.c3d`` or ``.csv`` capture (chosen by suffix)."""
    path = Path(path)
    readers = {".trc": read_trc, ".c3d": read_c3d, ".csv": read_csv}
    if not path.is_file():
        raise CaptureError(path, "file", "does not exist")
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise CaptureError(path, "file", f"unknown capture format {path.suffix!r}; expected .trc, .c3d or .csv")
    return reader(path, max_gap=max_gap)


# -- TRC --------------------------------------------------------------------
def read_trc(path: str | os.PathLike, max_gap: int = DEFAULT_MAX_GAP) -> Capture:
    """Read a TRC file (PathFileType 4, tab-separated)."""
    path = Path(path)
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise CaptureError(path, "line 1", "not a TRC file (expected 'PathFileType' header)")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    if len(values) < len(keys):
        raise CaptureError(path, "line 3", f"expected {len(keys)} header values, found {len(values)}")
    header = dict(zip((k.strip() for k in keys), values))
    for key in ("DataRate", "NumMarkers", "Units"):
        if key not in header:
            raise CaptureError(path, "line 2", f"missing header field {key!r}")
    try:
        rate = float(header["DataRate"])
        n_markers = int(header["NumMarkers"])
    except ValueError:
        raise CaptureError(path, "line 3", f"DataRate/NumMarkers not numbers: {header['DataRate']!r}, "
                                           f"{header['NumMarkers']!r}") from None
    units = _units(path, "line 3, field Units", header["Units"])
    names = [c.strip() for c in lines[3].split("\t")[2:] if c.strip()]
    if len(names) != n_markers:
        raise CaptureError(path, "line 4", f"NumMarkers is {n_markers} but {len(names)} marker names follow")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise CaptureError(path, "line 4", f"marker names must be distinct; repeated: {dup[:5]}")
    rows = []
    width = 2 + 3 * n_markers
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        if len(cells) < 2 or len(cells) > width + 1:
            raise CaptureError(path, f"line {number}", f"expected {width} tab-separated fields, found {len(cells)}")
        cells = (cells + [""] * width)[:width]
        try:
            rows.append([float(c) if c.strip() else math.nan for c in cells[2:]])
        except ValueError:
            bad = next(i for i, c in enumerate(cells[2:]) if c.strip() and not _is_number(c))
            raise CaptureError(path, f"line {number}, field {bad + 3}",
                               f"expected a number, found {cells[2 + bad]!r}") from None
    if not rows:
        raise CaptureError(path, "data", "no frames")
    markers = np.asarray(rows, dtype=np.float64).reshape(len(rows), n_markers, 3)
    return _finish(path, markers, names, rate, units, max_gap)


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def write_trc(path: str | os.PathLike, capture: Capture) -> Path:
    """Write ``capture`` as TRC (PathFileType 4); NaN samples become empty cells."""
    path = Path(path)
    n, m = capture.n_frames, capture.n_markers
    rate = f"{capture.rate:.2f}"
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n}\t{m}\t{capture.units}\t{rate}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{name}\t\t" for name in capture.names),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, m + 1)),
        "",
    ]
    body = []
    for f in range(n):
        cells = ["" if math.isnan(v) else f"{v:.6f}" for v in capture.markers[f].ravel().tolist()]
        body.append(f"{f + 1}\t{f / capture.rate:.6f}\t" + "\t".join(cells))
    path.write_text("\n".join(head + body) + "\n", encoding="utf-8")
    return path


# -- C3D --------------------------------------------------------------------
def read_c3d(path: str | os.PathLike, max_gap: int = DEFAULT_MAX_GAP) -> Capture:
    """Read a C3D file with the ``c3d`` package; residual < 0 marks an occluded sample."""
    import c3d

    path = Path(path)
    try:
        with open(path, "rb") as handle, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")  # kept, and said below with the file's name
            reader = c3d.Reader(handle)
            names = [str(n).strip() for n in reader.point_labels]
            units_param = reader.get("POINT:UNITS")
            units = _units(path, "POINT:UNITS", units_param.string_value if units_param else "")
            rate = float(reader.point_rate)
            declared = int(reader.header.last_frame) - int(reader.header.first_frame) + 1
            frames = [points[:, :4].copy() for _, points, _ in reader.read_frames()]
    except CaptureError:
        raise
    except Exception as exc:  # the c3d package raises assorted errors on damaged files
        raise CaptureError(path, "file", f"not a readable C3D file ({type(exc).__name__}: {exc})") from None
    if not frames:
        raise CaptureError(path, "data", "no frames")
    if declared > len(frames):
        raise CaptureError(path, "data", f"the header declares {declared} frames but the file holds {len(frames)}; "
                                         f"truncated?")
    said = [" ".join(str(w.message).split()) for w in caught if "No analog data" not in str(w.message)]
    if said:  # the package's warnings do not name the file: one line, with it
        warnings.warn(f"{path}: {len(said)} warnings reading the C3D file, first: {said[0]}", UserWarning,
                      stacklevel=2)
    data = np.stack(frames).astype(np.float64)
    markers = data[:, :, :3]
    markers[data[:, :, 3] < 0] = np.nan
    return _finish(path, markers, names, rate, units, max_gap)


def write_c3d(path: str | os.PathLike, capture: Capture) -> Path:
    """Write ``capture`` as float C3D; NaN samples get residual -1."""
    import c3d

    path = Path(path)
    writer = c3d.Writer(point_rate=float(capture.rate), point_scale=-1.0, point_units=f"{capture.units:<4}")
    writer.set_point_labels([f"{n:<16}" for n in capture.names])
    frames = []
    empty = np.zeros((0, 0), dtype=np.float32)
    for f in range(capture.n_frames):
        pts = np.zeros((capture.n_markers, 5), dtype=np.float32)
        xyz = capture.markers[f]
        bad = np.isnan(xyz).any(axis=1)
        pts[:, :3] = np.where(bad[:, None], 0.0, xyz)
        pts[bad, 3] = -1.0
        frames.append((pts, empty))
    writer.add_frames(frames)
    with open(path, "wb") as handle:
        writer.write(handle)
    return path


# -- CSV --------------------------------------------------------------------
def read_csv(path: str | os.PathLike, max_gap: int = DEFAULT_MAX_GAP, units: str | None = None,
             rate: float | None = None) -> Capture:
    """Read our plain CSV layout (see the module docstring)."""
    path = Path(path)
    meta: dict[str, tuple[int, str]] = {}
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise CaptureError(path, f"line {line}", f"not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    lines = text.splitlines()
    start = 0
    while start < len(lines) and lines[start].startswith("#"):
        key, _, value = lines[start][1:].partition(":")
        meta[key.strip().lower()] = (start + 1, value.strip())
        start += 1
    rows = list(csv.reader(lines[start:]))
    if not rows:
        raise CaptureError(path, f"line {start + 1}", "expected a header row")
    header = [h.strip() for h in rows[0]]
    lead = [h for h in header[:2] if h.lower() in ("frame", "time")]
    cols = header[len(lead):]
    if not cols or len(cols) % 3:
        raise CaptureError(path, f"line {start + 1}", f"expected marker columns in x/y/z triples, found {len(cols)}")
    names = []
    for i in range(0, len(cols), 3):
        base = [c[:-2] for c in cols[i:i + 3]]
        axes = [c[-2:].lower() for c in cols[i:i + 3]]
        if len(set(base)) != 1 or [a[-1] for a in axes] != ["x", "y", "z"] or axes[0][0] not in "_.:":
            raise CaptureError(path, f"line {start + 1}, column {len(lead) + i + 1}",
                               f"expected NAME_x, NAME_y, NAME_z, found {cols[i:i + 3]}")
        names.append(base[0])
    if units is None:
        if "units" not in meta:
            raise CaptureError(path, "header", "no '# units: cm' line (units must come from the file)")
        units = _units(path, f"line {meta['units'][0]}", meta["units"][1])
    values = []
    for number, row in enumerate(rows[1:], start=start + 2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise CaptureError(path, f"line {number}", f"expected {len(header)} fields, found {len(row)}")
        try:
            values.append([float(c) if c.strip() else math.nan for c in row])
        except ValueError:
            bad = next(i for i, c in enumerate(row) if c.strip() and not _is_number(c))
            raise CaptureError(path, f"line {number}, field {bad + 1} ({header[bad]})",
                               f"expected a number, found {row[bad]!r}") from None
    if not values:
        raise CaptureError(path, "data", "no frames")
    table = np.asarray(values, dtype=np.float64)
    if rate is None:
        if "rate" in meta:
            try:
                rate = float(meta["rate"][1])
            except ValueError:
                raise CaptureError(path, f"line {meta['rate'][0]}", f"rate not a number: {meta['rate'][1]!r}") from None
        elif "time" in [h.lower() for h in lead] and len(table) > 1:
            t = table[:, [h.lower() for h in lead].index("time")]
            step = float(np.median(np.diff(t))) if np.isfinite(t).all() else math.nan
            if not (step > 0 and math.isfinite(1.0 / step)):
                raise CaptureError(path, "time column", f"cannot give the frame rate: the median step between "
                                                        f"rows is {step!r} s (expected a positive time step)")
            rate = 1.0 / step
        else:
            raise CaptureError(path, "header", "no '# rate:' line and no time column to infer the frame rate")
    markers = table[:, len(lead):].reshape(len(table), len(names), 3)
    return _finish(path, markers, names, rate, units, max_gap)


def write_csv(path: str | os.PathLike, capture: Capture) -> Path:
    """Write ``capture`` in the plain CSV layout; NaN samples become empty cells."""
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        handle.write(f"# units: {capture.units}\n# rate: {capture.rate!r}\n")
        out = csv.writer(handle)
        out.writerow(["frame", "time"] + [f"{n}_{a}" for n in capture.names for a in "xyz"])
        for f in range(capture.n_frames):
            cells = ["" if math.isnan(v) else repr(v) for v in capture.markers[f].astype(np.float64).ravel().tolist()]
            out.writerow([f + 1, f"{f / capture.rate:.6f}"] + cells)
    return path
