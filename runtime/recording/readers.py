"""Recordings the runtime cannot read itself: readers registered by other packages.

``replay`` plays session files and Live Link Face CSV takes with the runtime's
own readers. Marker captures (TRC, C3D, marker CSV) are read by the offline
package (``facepuppet.offline.io.capture``; C3D needs its ``c3d`` dependency),
which the runtime never imports; instead the offline package registers a
:class:`RecordingReader` here when its commands are registered, and ``replay``
asks :func:`find_reader` before its own readers refuse a file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from facepuppet.runtime.frames import Frame


@dataclass(frozen=True)
class Recording:
    """Frames of a recording with what the chain needs to know about them.

    Attributes
    ----------
    frames : list of Frame, in time order
    kind : str, the input kind the frames are (``markers``)
    units : str or None, the units of marker positions (``mm``, ``cm``, ``m``)
    description : str, one line for the log (size, rate, units)
    """

    frames: list[Frame]
    kind: str
    units: str | None = None
    description: str = ""


@dataclass(frozen=True)
class RecordingReader:
    """``accepts(path, head)`` says from the name and first bytes whether ``read(path)`` applies."""

    name: str
    accepts: Callable[[Path, bytes], bool]
    read: Callable[[Path], Recording]


_READERS: dict[str, RecordingReader] = {}


def register_reader(reader: RecordingReader) -> None:
    """Add (or replace, by name) a reader."""
    _READERS[reader.name] = reader


def find_reader(path: Path, head: bytes) -> RecordingReader | None:
    """The first registered reader that accepts ``path`` (its first bytes ``head``), or None."""
    for reader in _READERS.values():
        if reader.accepts(path, head):
            return reader
    return None


def reader_names() -> tuple[str, ...]:
    return tuple(_READERS)
