"""Marker captures (TRC, C3D, marker CSV) as recordings ``replay`` can play through the solve stage."""

from __future__ import annotations

from pathlib import Path

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.livelinkface_csv import looks_like_llf_csv
from facepuppet.runtime.recording.readers import Recording, RecordingReader, register_reader

from facepuppet.offline.io.capture import read_capture

SUFFIXES = (".trc", ".c3d", ".csv")


def accepts(path: Path, head: bytes) -> bool:
    """A ``.trc``/``.c3d`` file, or a ``.csv`` that is not a Live Link Face take."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return not looks_like_llf_csv(head.split(b"\n", 1)[0].decode("utf-8", errors="replace"))
    return suffix in (".trc", ".c3d")


def read(path: Path) -> Recording:
    """One markers frame per capture frame, at ``i / rate`` s, NaN where occluded after gap filling."""
    capture = read_capture(path)
    names = tuple(capture.names)
    frames = [Frame(t=i / capture.rate, source="markers", markers=capture.markers[i], marker_names=names,
                    t_sender=i / capture.rate, number=i) for i in range(capture.n_frames)]
    return Recording(frames, "markers", capture.units,
                     f"marker take, {capture.n_frames} frames x {capture.n_markers} markers, "
                     f"{capture.rate:g} Hz, {capture.units}")


def register() -> None:
    """Let ``replay`` play marker captures."""
    register_reader(RecordingReader("marker capture (TRC, C3D, CSV)", accepts, read))
