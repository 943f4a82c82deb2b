"""Session files: an append-only, crash-safe record of timestamped frames.

Layout of a file (all integers little-endian)::

    magic     8 bytes   b"FPSESS\\x00\\x01"  (format name, major 0, minor 1)
    record*   u32 payload length | u32 crc32(payload) | u8 kind | payload

The first record is always a ``HEADER`` (JSON: created, facepuppet version,
free-form info). Records of other kinds follow in the order written:

========  ====  ==============================================================
kind      code  payload
========  ====  ==============================================================
HEADER    0     UTF-8 JSON object
LAYOUT    1     UTF-8 JSON ``{"id", "source", "channels", "marker_names",
                "n_markers"}``: what the following frames with this layout id
                carry. Written automatically the first time a frame with a new
                (source, channels, markers) combination is written.
FRAME     2     ``t f64, t_sender f64, number i64, layout id u32, flags u8``,
                then, each present only when its flag bit is set, in this
                order: weights f32[n_channels], head rotation f32[4] (x, y, z,
                w), head translation f32[3], audio level f32 (dBFS), markers
                f32[n_markers * 3]
PACKET    3     live recording: ``b"P1"``, receive time f64 (monotonic s),
                input kind length u16, input kind UTF-8, then the datagram's
                raw bytes
AUDIO     4     live recording: ``b"A1"``, tick time f64 (s), level f32 (dBFS)
TICK      5     live recording: ``b"K1"``, tick index i64, tick time f64 (s
                since the loop started), frames i64 (frames the source had
                completed when the tick took its snapshot), snapshot time f64
                (monotonic s, the packets' clock); lets a replay tick as the
                live run did (same frames at the same tick times)
========  ====  ==============================================================

A reader skips PACKET/AUDIO/TICK records it cannot decode (older readers skip them
all; their length is in the record header) and counts them in
``Session.skipped``; any other unknown code is corruption.

Crash safety: :class:`SessionWriter` writes each record with one ``os.write``
on an unbuffered descriptor opened with ``O_APPEND``, so a ``kill -9`` can at
worst lose or tear the last record; :func:`read_session` keeps every complete
record before a torn or corrupt one and says where it stopped.
"""

from __future__ import annotations

import enum
import json
import math
import os
import struct
import time
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .frames import Frame

MAGIC = b"FPSESS\x00\x01"

_RECORD_HEAD = struct.Struct("<IIB")  # payload length, crc32 of payload, kind
_FRAME_HEAD = struct.Struct("<ddqIB")  # t, t_sender, number, layout id, flags
_PACKET_HEAD = struct.Struct("<2sdH")  # b"P1", receive time, input kind length
_AUDIO = struct.Struct("<2sdf")  # b"A1", time, level dBFS
_TICK = struct.Struct("<2sqdqd")  # b"K1", tick index, tick time, frames completed, snapshot time
_MAX_PAYLOAD = 1 << 30  # a length above this is corruption, not data


class RecordKind(enum.IntEnum):
    """Record kind codes; new kinds get new codes, codes are never reused."""

    HEADER = 0
    LAYOUT = 1
    FRAME = 2
    PACKET = 3  # live recording: raw bytes + receive time + input kind
    AUDIO = 4  # live recording: audio levels
    TICK = 5  # live recording: which frame each tick took, and when


_RESERVED_KINDS = frozenset({RecordKind.PACKET, RecordKind.AUDIO, RecordKind.TICK})


class FrameFlags(enum.IntFlag):
    """Which optional parts a FRAME record carries."""

    WEIGHTS = 1
    HEAD_ROTATION = 2
    HEAD_TRANSLATION = 4
    AUDIO_LEVEL = 8
    MARKERS = 16


@dataclass(frozen=True)
class _Layout:
    source: str
    channels: tuple[str, ...] | None
    marker_names: tuple[str, ...] | None
    n_markers: int

    def to_json(self, layout_id: int) -> dict:
        return {
            "id": layout_id,
            "source": self.source,
            "channels": None if self.channels is None else list(self.channels),
            "marker_names": None if self.marker_names is None else list(self.marker_names),
            "n_markers": self.n_markers,
        }


def _layout_of(frame: Frame) -> _Layout:
    n_markers = 0 if frame.markers is None else int(frame.markers.shape[0])
    return _Layout(frame.source, frame.channels, frame.marker_names, n_markers)


class SessionWriter:
    """Append frames to a new session file, one complete record per write.

    Parameters
    ----------
    path : str or Path, the session file to create
    info : dict, free-form JSON-serialisable information for the header
    fsync_every_s : float or None, seconds between fsyncs (0: after every
        record; None: only on close). Default 1 s.
    overwrite : bool, replace an existing file (default: refuse, FileExistsError)

    Use as a context manager; :meth:`close` fsyncs and closes the descriptor.
    Not thread-safe: one thread writes.
    """

    def __init__(self, path, info: dict | None = None, fsync_every_s: float | None = 1.0,
                 overwrite: bool = False):
        from facepuppet import __version__

        self.path = Path(path)
        self.fsync_every_s = fsync_every_s
        self.n_records = 0
        self._layouts: dict[_Layout, int] = {}
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | getattr(os, "O_BINARY", 0)
        flags |= os.O_TRUNC if overwrite else os.O_EXCL
        self._fd: int | None = os.open(self.path, flags, 0o644)
        self._last_sync = time.monotonic()
        header = {
            "format": "facepuppet session",
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "facepuppet_version": __version__,
            "info": dict(info or {}),
        }
        payload = json.dumps(header, sort_keys=True).encode("utf-8")
        # Magic and header go out in one write: a file is either empty or has both.
        self._write(MAGIC + _record(RecordKind.HEADER, payload))

    def __enter__(self) -> "SessionWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def write_frame(self, frame: Frame) -> None:
        """Append one FRAME record (preceded by a LAYOUT record when its layout is new)."""
        layout = _layout_of(frame)
        layout_id = self._layouts.get(layout)
        if layout_id is None:
            layout_id = len(self._layouts)
            self._layouts[layout] = layout_id
            self.write_record(RecordKind.LAYOUT, json.dumps(layout.to_json(layout_id)).encode("utf-8"))
        self.write_record(RecordKind.FRAME, encode_frame(frame, layout_id))

    def write_record(self, kind: RecordKind, payload: bytes) -> None:
        """Append one record of any kind with a single write (for PACKET/AUDIO recorders)."""
        self._write(_record(RecordKind(kind), payload))

    def _write(self, data: bytes) -> None:
        if self._fd is None:
            raise ValueError(f"{self.path}: session writer is closed")
        view = memoryview(data)
        while view:  # a regular file takes it all at once; loop only for safety
            view = view[os.write(self._fd, view):]
        self.n_records += 1
        if self.fsync_every_s is not None and time.monotonic() - self._last_sync >= self.fsync_every_s:
            os.fsync(self._fd)
            self._last_sync = time.monotonic()

    def close(self) -> None:
        if self._fd is not None:
            os.fsync(self._fd)
            os.close(self._fd)
            self._fd = None


def _record(kind: RecordKind, payload: bytes) -> bytes:
    if len(payload) > _MAX_PAYLOAD:
        raise ValueError(f"session record payload: expected at most {_MAX_PAYLOAD} bytes, got {len(payload)}")
    return _RECORD_HEAD.pack(len(payload), zlib.crc32(payload), int(kind)) + payload


def encode_frame(frame: Frame, layout_id: int) -> bytes:
    """FRAME payload of ``frame`` under ``layout_id`` (see the module docstring)."""
    flags = 0
    parts = []
    if frame.weights is not None:
        flags |= FrameFlags.WEIGHTS
        parts.append(frame.weights.astype("<f4", copy=False).tobytes())
    if frame.head_rotation is not None:
        flags |= FrameFlags.HEAD_ROTATION
        parts.append(frame.head_rotation.astype("<f4", copy=False).tobytes())
    if frame.head_translation is not None:
        flags |= FrameFlags.HEAD_TRANSLATION
        parts.append(frame.head_translation.astype("<f4", copy=False).tobytes())
    if not math.isnan(frame.audio_level):
        flags |= FrameFlags.AUDIO_LEVEL
        parts.append(struct.pack("<f", frame.audio_level))
    if frame.markers is not None:
        flags |= FrameFlags.MARKERS
        parts.append(frame.markers.astype("<f4", copy=False).tobytes())
    head = _FRAME_HEAD.pack(frame.t, frame.t_sender, frame.number, layout_id, flags)
    return head + b"".join(parts)


@dataclass(frozen=True)
class Packet:
    """One received datagram of a live recording.

    Attributes
    ----------
    t : float, receive time, seconds on the monotonic clock
    kind : str, the input kind that decoded it ("vmc", "livelinkface", ...)
    data : bytes, the datagram as received
    """

    t: float
    kind: str
    data: bytes


def encode_packet(t: float, kind: str, data: bytes) -> bytes:
    """PACKET payload (see the module docstring)."""
    name = kind.encode("utf-8")
    return _PACKET_HEAD.pack(b"P1", t, len(name)) + name + bytes(data)


def encode_audio(t: float, level_db: float) -> bytes:
    """AUDIO payload (see the module docstring)."""
    return _AUDIO.pack(b"A1", t, level_db)


@dataclass(frozen=True)
class Tick:
    """One drawn tick of a live recording.

    Attributes
    ----------
    k : int, tick index (t = k / fps)
    t : float, tick time, seconds since the frame loop started
    frames : int, frames the live source had completed when this tick took its snapshot
    t_clock : float, the snapshot's time on the monotonic clock (the packets' receive clock)
    """

    k: int
    t: float
    frames: int
    t_clock: float


def encode_tick(k: int, t: float, frames: int, t_clock: float) -> bytes:
    """TICK payload (see the module docstring)."""
    return _TICK.pack(b"K1", int(k), float(t), int(frames), float(t_clock))


def _decode_packet(payload: bytes) -> Packet | None:
    if len(payload) < _PACKET_HEAD.size or payload[:2] != b"P1":
        return None
    _, t, n = _PACKET_HEAD.unpack_from(payload)
    end = _PACKET_HEAD.size + n
    if end > len(payload):
        return None
    try:
        kind = payload[_PACKET_HEAD.size:end].decode("utf-8")
    except UnicodeDecodeError:
        return None
    return Packet(t, kind, bytes(payload[end:]))


def _decode_frame(payload: bytes, layouts: dict[int, _Layout]) -> Frame:
    """Frame from a FRAME payload; ValueError when it does not fit its layout."""
    if len(payload) < _FRAME_HEAD.size:
        raise ValueError(f"frame record of {len(payload)} bytes, shorter than its {_FRAME_HEAD.size}-byte head")
    t, t_sender, number, layout_id, flags = _FRAME_HEAD.unpack_from(payload)
    layout = layouts.get(layout_id)
    if layout is None:
        raise ValueError(f"frame refers to layout id {layout_id}, which no earlier LAYOUT record defined")
    if flags & ~0x1F:
        raise ValueError(f"frame flags 0x{flags:02x} have unknown bits")
    n_ch = 0 if layout.channels is None else len(layout.channels)
    sizes = (
        (FrameFlags.WEIGHTS, "weights", n_ch),
        (FrameFlags.HEAD_ROTATION, "head_rotation", 4),
        (FrameFlags.HEAD_TRANSLATION, "head_translation", 3),
        (FrameFlags.AUDIO_LEVEL, "audio_level", 1),
        (FrameFlags.MARKERS, "markers", layout.n_markers * 3),
    )
    expected = _FRAME_HEAD.size + 4 * sum(n for flag, _, n in sizes if flags & flag)
    if len(payload) != expected:
        raise ValueError(f"frame record of {len(payload)} bytes, its flags and layout need {expected}")
    values = np.frombuffer(payload, dtype="<f4", offset=_FRAME_HEAD.size)
    parts: dict = {}
    at = 0
    for flag, name, n in sizes:
        if flags & flag:
            parts[name] = values[at:at + n]
            at += n
    markers = parts.get("markers")
    return Frame(
        t=t,
        source=layout.source,
        channels=layout.channels,
        weights=parts.get("weights"),
        head_rotation=parts.get("head_rotation"),
        head_translation=parts.get("head_translation"),
        audio_level=float(parts["audio_level"][0]) if "audio_level" in parts else math.nan,
        markers=None if markers is None else markers.reshape(-1, 3),
        marker_names=layout.marker_names if markers is not None else None,
        t_sender=t_sender,
        number=number,
    )


def _decode_layout(payload: bytes) -> tuple[int, _Layout]:
    try:
        obj = json.loads(payload.decode("utf-8"))
        channels = obj["channels"]
        marker_names = obj["marker_names"]
        layout = _Layout(
            str(obj["source"]),
            None if channels is None else tuple(str(c) for c in channels),
            None if marker_names is None else tuple(str(m) for m in marker_names),
            int(obj["n_markers"]),
        )
        return int(obj["id"]), layout
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"layout record is not the expected JSON object: {exc}") from None


@dataclass
class Session:
    """What :func:`read_session` recovered from a session file.

    Attributes
    ----------
    path : Path
    header : dict, the HEADER record's JSON ({} when even that was torn)
    frames : list of Frame, every complete frame, in file order
    complete : bool, False when reading stopped before the end of the file
    n_records : int, complete records read (header, layouts, frames, reserved kinds)
    tail_error : str, why and at which byte offset reading stopped ("" when complete)
    skipped : dict of str to int, PACKET/AUDIO records this reader could not decode
    packets : list of Packet, the received datagrams of a live recording, in file order
    audio_levels : list of (t, level_db) float pairs, the audio levels of a live recording
    ticks : list of Tick, the drawn ticks of a live recording (recordings made since TICK existed)
    """

    path: Path
    header: dict
    frames: list[Frame]
    complete: bool
    n_records: int
    tail_error: str = ""
    skipped: dict[str, int] = field(default_factory=dict)
    packets: list[Packet] = field(default_factory=list)
    audio_levels: list[tuple[float, float]] = field(default_factory=list)
    ticks: list[Tick] = field(default_factory=list)


def read_session(path) -> Session:
    """Read a session file, keeping every complete record before a torn or corrupt one.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Session ; ``complete`` is False (and one warning is issued) when the last
    record is torn (short or bad CRC, as after a crash) or a record in the
    middle is corrupt; ``tail_error`` names the byte offset.

    Raises
    ------
    ValueError
        when the file does not start with the session magic.
    """
    path = Path(path)
    data = path.read_bytes()
    if data[: len(MAGIC)] != MAGIC:
        raise ValueError(
            f"{path}: not a facepuppet session file (expected magic {MAGIC!r}, found {data[:len(MAGIC)]!r})"
        )
    session = Session(path=path, header={}, frames=[], complete=True, n_records=0)
    layouts: dict[int, _Layout] = {}
    offset = len(MAGIC)
    end = len(data)
    while offset < end:
        problem = None
        if end - offset < _RECORD_HEAD.size:
            problem = f"torn record header ({end - offset} of {_RECORD_HEAD.size} bytes)"
        else:
            length, crc, kind = _RECORD_HEAD.unpack_from(data, offset)
            start = offset + _RECORD_HEAD.size
            payload = data[start:start + length]
            if len(payload) < length:
                problem = f"torn record ({len(payload)} of {length} payload bytes)"
            elif zlib.crc32(payload) != crc:
                where = "last record" if start + length == end else "record in the middle of the file"
                problem = f"CRC mismatch in the {where}"
            else:
                try:
                    _apply_record(session, layouts, kind, payload, first=offset == len(MAGIC))
                except ValueError as exc:
                    problem = f"corrupt record of kind {kind}: {exc}"
        if problem is not None:
            session.complete = False
            session.tail_error = f"{path}: {problem} at byte offset {offset}; kept the {session.n_records} records before it"
            warnings.warn(session.tail_error, stacklevel=2)
            break
        session.n_records += 1
        offset = start + length
    return session


def _apply_record(session: Session, layouts: dict[int, _Layout], kind: int, payload: bytes, first: bool) -> None:
    if first != (kind == RecordKind.HEADER):
        raise ValueError("the header must be the first record, and only the first")
    if kind == RecordKind.HEADER:
        try:
            session.header = json.loads(payload.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"header is not JSON: {exc}") from None
    elif kind == RecordKind.LAYOUT:
        layout_id, layout = _decode_layout(payload)
        layouts[layout_id] = layout
    elif kind == RecordKind.FRAME:
        session.frames.append(_decode_frame(payload, layouts))
    elif kind == RecordKind.PACKET and (packet := _decode_packet(payload)) is not None:
        session.packets.append(packet)
    elif kind == RecordKind.AUDIO and len(payload) == _AUDIO.size and payload[:2] == b"A1":
        _, t, level = _AUDIO.unpack(payload)
        session.audio_levels.append((t, level))
    elif kind == RecordKind.TICK and len(payload) == _TICK.size and payload[:2] == b"K1":
        _, k, t, frames, t_clock = _TICK.unpack(payload)
        session.ticks.append(Tick(k, t, frames, t_clock))
    elif kind in _RESERVED_KINDS:
        name = RecordKind(kind).name.lower()
        session.skipped[name] = session.skipped.get(name, 0) + 1
    else:
        raise ValueError(f"unknown record kind code {kind}")
