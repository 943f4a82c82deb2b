"""Live Link Face CSV recordings (PROTOCOLS.md §5) read as a list of frames.

Columns are mapped by header **name**, never by position: the CSV order is not
the UDP packet's (``JawRight,JawLeft`` and ``MouthRight,MouthLeft`` are
swapped there).

==========================  =================================================
column                      becomes
==========================  =================================================
``Timecode``                ``t`` (seconds since the first row) and
                            ``t_sender`` (absolute timecode seconds), ``number``
                            (timecode frame count at 60 fps)
``BlendShapeCount``         ignored
``HeadYaw/Pitch/Roll``      ``head_rotation`` (radians, via
                            :func:`~facepuppet.runtime.model.geometry.euler_to_quat`)
``Left/RightEyeYaw...``     ignored: eye rotations are not channels (the rig's
                            eyeLook* shapes carry gaze)
every other column          a weight channel, named as in the header
                            (``JawOpen``); :mod:`facepuppet.runtime.mapping.channels` maps spellings
==========================  =================================================

Timecode ``HH:MM:SS:FF.fff`` counts 60 frames per second, ``.fff`` being the
sub-frame: seconds = h·3600 + m·60 + s + FF.fff/60.

Rows must be in time order. A timecode that goes backwards is an error
(ValueError naming the line), not something to sort away: it means the file
was concatenated or damaged, and reordering would hide that. Equal timecodes
are allowed (the replay keeps the later row).
"""

from __future__ import annotations

import csv
import io
import math
import re
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.geometry import euler_to_quat

if TYPE_CHECKING:
    import os

SOURCE = "livelinkface_csv"
TIMECODE_FPS = 60.0

_TIMECODE = re.compile(r"^(\d{1,2}):(\d{2}):(\d{2}):(\d{1,2}(?:\.\d+)?)$")
_IGNORED = frozenset({
    "BlendShapeCount",
    "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
    "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
})
_HEAD = ("HeadYaw", "HeadPitch", "HeadRoll")


def parse_timecode(text: str, fps: float = TIMECODE_FPS) -> tuple[float, int]:
    """(seconds, whole frame count) of an ``HH:MM:SS:FF.fff`` timecode; ValueError if malformed."""
    m = _TIMECODE.match(text.strip())
    if m is None:
        raise ValueError(f"expected a timecode HH:MM:SS:FF.fff, found {text!r}")
    h, mi, s = int(m.group(1)), int(m.group(2)), int(m.group(3))
    ff = float(m.group(4))
    if mi >= 60 or s >= 60 or ff >= fps:
        raise ValueError(f"timecode {text!r} out of range (minutes, seconds < 60, frames < {fps:g})")
    whole = h * 3600 + mi * 60 + s
    return whole + ff / fps, int(whole * fps) + int(ff)


def read_llf_csv(path: str | os.PathLike, fps: float = TIMECODE_FPS) -> list[Frame]:
    """Frames of a Live Link Face CSV recording.

    Parameters
    ----------
    path : str or Path
    fps : float, timecode frames per second (Live Link Face records 60)

    Returns
    -------
    list of Frame, one per data row: ``t`` seconds since the first row,
    ``t_sender`` absolute timecode seconds, ``weights`` (n_channels,) float32
    named by the header (e.g. ``"JawOpen"``), ``head_rotation`` (4,) float32
    (x, y, z, w) when the HeadYaw/HeadPitch/HeadRoll columns exist.

    Raises
    ------
    ValueError
        naming the file, line and column: no ``Timecode`` column, a duplicated
        column, a malformed or backwards timecode, a cell that is not a number,
        a row with the wrong number of cells, or no data rows.
    """
    path = regular_file(path, "Live Link Face CSV")
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise InputFileError(f"{path}, line {line}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    out_of_range = 0
    first_bad = ""
    with io.StringIO(text, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            raise InputFileError(f"{path}: empty file, expected a Live Link Face CSV header")
        header = [h.strip() for h in header]
        index = _column_index(path, header)
        channel_cols = [i for i, name in enumerate(header)
                        if name != "Timecode" and name not in _IGNORED and name not in _HEAD]
        channels = tuple(header[i] for i in channel_cols)
        head_cols = [index[n] for n in _HEAD] if all(n in index for n in _HEAD) else None
        tc_col = index["Timecode"]
        frames: list[Frame] = []
        t0 = prev = None
        for row in reader:
            line = reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue  # blank line (e.g. at the end)
            if len(row) != len(header):
                raise InputFileError(f"{path}, line {line}: {len(row)} cells, the header has {len(header)} columns")
            try:
                t_abs, number = parse_timecode(row[tc_col], fps)
            except ValueError as exc:
                raise InputFileError(f"{path}, line {line}, column 'Timecode': {exc}") from None
            if prev is not None and t_abs < prev:
                raise InputFileError(
                    f"{path}, line {line}, column 'Timecode': {row[tc_col]} goes back in time "
                    f"({t_abs:.4f} s after {prev:.4f} s); rows must be in time order"
                )
            prev = t_abs
            if t0 is None:
                t0 = t_abs
            values = [_number(path, line, header, row, i) for i in channel_cols]
            with np.errstate(over="ignore"):  # beyond float32: inf, counted here, dropped by the loop
                weights = np.array(values, dtype=np.float32)
            rotation = None
            if head_cols is not None:
                yaw, pitch, roll = (_number(path, line, header, row, i) for i in head_cols)
                if all(math.isfinite(a) for a in (yaw, pitch, roll)):
                    rotation = euler_to_quat(yaw, pitch, roll)
                else:
                    out_of_range += 1  # the row's pose is unknown: no head rotation (counted below)
                    first_bad = first_bad or f"line {line}"
            if not np.isfinite(weights).all():
                out_of_range += 1
                first_bad = first_bad or f"line {line}"
            frames.append(Frame(
                t=t_abs - t0, source=SOURCE, channels=channels, weights=weights,
                head_rotation=rotation, t_sender=t_abs, number=number,
            ))
    if not frames:
        raise InputFileError(f"{path}: no data rows after the header")
    if out_of_range:
        warnings.warn(f"{path}: {out_of_range} rows hold NaN, infinite or out-of-range numbers (first at "
                      f"{first_bad}); the frame loop drops those frames", UserWarning, stacklevel=2)
    return frames


def _column_index(path: Path, header: list[str]) -> dict[str, int]:
    index: dict[str, int] = {}
    for i, name in enumerate(header):
        if name in index:
            raise InputFileError(f"{path}, line 1: column {name!r} appears twice "
                                 f"(columns {index[name] + 1} and {i + 1})")
        index[name] = i
    if "Timecode" not in index:
        raise InputFileError(f"{path}, line 1: no 'Timecode' column; expected a Live Link Face CSV header, "
                         f"found columns {header[:4]}...")
    return index


def _number(path: Path, line: int, header: list[str], row: list[str], col: int) -> float:
    try:
        return float(row[col])
    except ValueError:
        raise InputFileError(
            f"{path}, line {line}, column {header[col]!r}: expected a number, found {row[col]!r}"
        ) from None


def looks_like_llf_csv(first_line: str) -> bool:
    """True when a CSV header line names a ``Timecode`` column and a ``BlendShapeCount`` column."""
    names = {c.strip() for c in first_line.lstrip("\ufeff").split(",")}
    return "Timecode" in names and "BlendShapeCount" in names
