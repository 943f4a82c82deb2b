"""Session files: an append-only, crash-safe record of timestamped frames (framing, writer, reader).

Layout of a file (all integers little-endian)::

    magic     8 bytes   b"FPSESS\\x00\\x01"  (format name, major 0, minor 1)
    record*   u32 payload length | u32 crc32(payload) | u8 kind | payload

The first record is always a ``HEADER`` (JSON: created, facepuppet version,
free-form info). Records of other kinds (LAYOUT, FRAME, PACKET, AUDIO, TICK)
follow in the order written; the kind codes and each kind's payload are in
:mod:`facepuppet.runtime.recording.records`.

A reader skips PACKET/AUDIO/TICK records it cannot decode (older readers skip them
all; their length is in the record header) and counts them in
``Session.skipped``; any other unknown code is corruption.

JSON in a record (the header, LAYOUT) is read within the limits of
:mod:`~facepuppet.runtime.files.json_limits`; a whole record over them is
refused (InputFileError naming the file, the kind and the offset), not taken
for damage.

Crash safety: :class:`SessionWriter` writes each record with one ``os.write``
on an unbuffered descriptor opened with ``O_APPEND``, so a ``kill -9`` can at
worst lose or tear the last record; :func:`read_session` keeps every complete
record before a torn tail and says where it stopped. A damaged record in the
middle (a flipped bit) is skipped: reading resumes at the next offset where a
whole record verifies (known kind, length within the file, CRC; found in
time linear in the file's size, :mod:`~facepuppet.runtime.recording.resync`),
and the bytes skipped are counted.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import stat
import struct
import time
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.files.json_limits import JsonLimitError, JsonTextError, loads_limited
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.records import (
    RESERVED_KINDS,
    Layout,
    Packet,
    RecordKind,
    Tick,
    decode_audio,
    decode_config,
    decode_control,
    decode_event,
    decode_frame,
    decode_layout,
    decode_packet_record,
    decode_sources,
    decode_state,
    decode_tick,
    decode_voice,
    encode_frame,
    layout_of,
)
from facepuppet.runtime.recording.resync import MAX_PAYLOAD, Prefixes, next_record

from facepuppet import __version__

MAGIC = b"FPSESS\x00\x01"

_RECORD_HEAD = struct.Struct("<IIB")  # payload length, crc32 of payload, kind


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

    A write that fails (disk full, the file-size limit) raises its OSError once the file is cut back to the
    end of the last whole record (``size``), so what was written reads without a torn tail; a header that
    cannot be written leaves no file behind (where the writer created it).

    Attributes
    ----------
    n_records : int, whole records written (the header included)
    size : int, bytes of whole records in the file (the magic included)
    """

    def __init__(self, path: str | os.PathLike, info: dict | None = None, fsync_every_s: float | None = 1.0,
                 overwrite: bool = False) -> None:
        self.path = Path(path)
        self.fsync_every_s = fsync_every_s
        self.n_records = 0
        self.size = 0
        self._layouts: dict[Layout, int] = {}
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
        try:
            self._write(MAGIC + _record(RecordKind.HEADER, payload))
        except OSError as exc:
            created = not overwrite and stat.S_ISREG(os.fstat(self._fd).st_mode)
            self._close_quietly()
            if created:  # the empty file this writer made, never a file it was given (nor a device)
                with contextlib.suppress(OSError):
                    self.path.unlink()
            raise OSError(exc.errno, f"{self.path}: cannot write a recording's header: "
                                     f"{exc.strerror or exc}") from exc

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def write_frame(self, frame: Frame) -> None:
        """Append one FRAME record (preceded by a LAYOUT record when its layout is new)."""
        layout = layout_of(frame)
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
        try:
            while view:  # a regular file takes it all at once, or part of it when the disk or the limit is reached
                view = view[os.write(self._fd, view):]
        except OSError:
            with contextlib.suppress(OSError):  # shrinking needs no space and is within any size limit
                os.ftruncate(self._fd, self.size)
            raise
        self.n_records += 1
        self.size += len(data)
        if self.fsync_every_s is not None and time.monotonic() - self._last_sync >= self.fsync_every_s:
            os.fsync(self._fd)
            self._last_sync = time.monotonic()

    def close(self) -> None:
        """fsync and close; raises the OSError of a failed fsync (the descriptor closed all the same)."""
        if self._fd is not None:
            try:
                os.fsync(self._fd)
            finally:
                self._close_quietly()

    def _close_quietly(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


def _record(kind: RecordKind, payload: bytes) -> bytes:
    if len(payload) > MAX_PAYLOAD:  # what a reader resynchronising after damage looks for
        raise ValueError(f"session record payload: expected at most {MAX_PAYLOAD} bytes, got {len(payload)}")
    return _RECORD_HEAD.pack(len(payload), zlib.crc32(payload), int(kind)) + payload


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
    configs : list of (tick time, TOML text), the live config changes of a live recording (CONFIG records)
    events : list of (tick time, found) pairs, the tracking lost (False) / found (True) events of a live run
    sources : list of (tick index, frames per mix source), one per tick of a run with several inputs
    states : list of (tick time, JSON text), the filter stage's state where a recording started mid-run (STATE)
    voice : list of (tick time, channels float32), the voice's mouth channels of a ``--voice`` run (VOICE)
    controls : list of (tick time, JSON object), the control commands applied during a live run (CONTROL)
    skipped_bytes : int, bytes skipped over damaged records in the middle of the file
    damaged : list of (byte offset, bytes skipped), each damaged stretch that reading resynchronised past
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
    configs: list[tuple[float, str]] = field(default_factory=list)
    events: list[tuple[float, bool]] = field(default_factory=list)
    sources: list[tuple[int, tuple[int, ...]]] = field(default_factory=list)
    states: list[tuple[float, str]] = field(default_factory=list)
    voice: list = field(default_factory=list)
    controls: list[tuple[float, dict]] = field(default_factory=list)
    skipped_bytes: int = 0
    damaged: list[tuple[int, int]] = field(default_factory=list)


def read_session(path: str | os.PathLike) -> Session:
    """Read a session file, keeping every complete record before a torn or corrupt one.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Session ; ``complete`` is False (and one warning is issued) when the last
    record is torn (short or bad CRC, as after a crash) or records in the
    middle were damaged and skipped (``skipped_bytes``, ``damaged``);
    ``tail_error`` says what and at which byte offsets.

    Raises
    ------
    ValueError
        when the file does not start with the session magic.
    """
    path = regular_file(path, "session file")
    data = path.read_bytes()
    if data[: len(MAGIC)] != MAGIC:
        raise InputFileError(
            f"{path}: not a facepuppet session file (expected magic {MAGIC!r}, found {data[:len(MAGIC)]!r})"
        )
    session = Session(path=path, header={}, frames=[], complete=True, n_records=0)
    layouts: dict[int, Layout] = {}
    prefixes = Prefixes(data)
    offset = len(MAGIC)
    end = len(data)
    while offset < end:
        problem, next_offset = _next_record(session, layouts, data, offset)
        if problem is None:
            session.n_records += 1
            offset = next_offset
            continue
        session.complete = False
        found = next_record(data, offset + 1, _RESYNC_KINDS, prefixes)
        if found is None:  # nothing valid after it: a torn or corrupt tail (as after a crash)
            session.tail_error = (f"{path}: {problem} at byte offset {offset}; "
                                  f"kept the {session.n_records} records before it")
            break
        session.skipped_bytes += found - offset
        session.damaged.append((offset, found - offset))
        offset = found
    if session.damaged:
        first = session.damaged[0][0]
        resumed = (f"{path}: {len(session.damaged)} damaged stretches ({session.skipped_bytes} bytes, at least "
                   f"{len(session.damaged)} records) skipped, the first at byte offset {first}; reading resumed "
                   f"at the next valid record each time and kept {session.n_records} records")
        session.tail_error = resumed + ("; " + session.tail_error if session.tail_error else "")
    if not session.complete:
        warnings.warn(session.tail_error, stacklevel=2)
    _check_header(path, session.header)
    return session


def _next_record(session: Session, layouts: dict[int, Layout], data: bytes, offset: int
                 ) -> tuple[str | None, int]:
    """Apply the record at ``offset``: (None, offset of the next record), or (what is wrong with it, offset)."""
    end = len(data)
    if end - offset < _RECORD_HEAD.size:
        return f"torn record header ({end - offset} of {_RECORD_HEAD.size} bytes)", offset
    length, crc, kind = _RECORD_HEAD.unpack_from(data, offset)
    start = offset + _RECORD_HEAD.size
    payload = data[start:start + length]
    if len(payload) < length:
        return f"torn record ({len(payload)} of {length} payload bytes)", offset
    if zlib.crc32(payload) != crc:
        where = "last record" if start + length == end else "record in the middle of the file"
        return f"CRC mismatch in the {where}", offset
    try:
        _apply_record(session, layouts, kind, payload, first=offset == len(MAGIC))
    except JsonLimitError as exc:  # whole and CRC'd, so not damage: made to be refused
        raise InputFileError(f"{session.path}: {RecordKind(kind).name} record at byte offset {offset}: "
                             f"{exc.problem}") from None
    except ValueError as exc:
        return f"corrupt record of kind {kind}: {exc}", offset
    return None, start + length


_RESYNC_KINDS = frozenset(int(k) for k in RecordKind if k != RecordKind.HEADER)  # the header is only first


def _number_field(value: object) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            and value > 0)


def _names(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


def _sources(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(v, dict) and isinstance(v.get("name"), str)
                                           and isinstance(v.get("kind"), str) for v in value)


_INFO_FIELDS = {  # the header's info fields a reader uses: (check, what it must be)
    "fps": (_number_field, "a positive number"),
    "idle_fps": (lambda v: v is None or _number_field(v), "a positive number or null"),
    "input": (lambda v: isinstance(v, str), "a string"),
    "options": (lambda v: v is None or isinstance(v, dict), "a JSON object or null"),
    "inputs": (lambda v: v is None or _names(v), "a list of source names or null"),
    "mix_sources": (lambda v: v is None or _sources(v), "a list of {name, kind} objects or null"),
}


def _check_header(path: Path, header: object) -> None:
    """The HEADER record, when one was read, is an object whose ``info`` fields have the types readers use."""
    if not isinstance(header, dict):
        raise InputFileError(f"{path}: session header: expected a JSON object, found {type(header).__name__}")
    if "info" not in header:
        return
    info = header["info"]
    if not isinstance(info, dict):
        raise InputFileError(f"{path}: session header field 'info': expected a JSON object, found "
                             f"{type(info).__name__} {str(info)[:40]!r}")
    for key, (ok, what) in _INFO_FIELDS.items():
        if key in info and not ok(info[key]):
            raise InputFileError(f"{path}: session header field 'info.{key}': expected {what}, found "
                                 f"{str(info[key])[:40]!r}")


def _apply_record(session: Session, layouts: dict[int, Layout], kind: int, payload: bytes, first: bool) -> None:
    if first != (kind == RecordKind.HEADER):
        raise ValueError("the header must be the first record, and only the first")
    if kind == RecordKind.HEADER:
        try:
            session.header = loads_limited(payload, "header")
        except JsonLimitError:
            raise
        except JsonTextError as exc:
            raise ValueError(f"header {exc.problem}") from None
    elif kind == RecordKind.LAYOUT:
        layout_id, layout = decode_layout(payload)
        layouts[layout_id] = layout
    elif kind == RecordKind.FRAME:
        session.frames.append(decode_frame(payload, layouts))
    elif kind == RecordKind.PACKET and (packet := decode_packet_record(payload)) is not None:
        session.packets.append(packet)
    elif kind == RecordKind.AUDIO and (level := decode_audio(payload)) is not None:
        session.audio_levels.append(level)
    elif kind == RecordKind.TICK and (tick := decode_tick(payload)) is not None:
        session.ticks.append(tick)
    elif kind == RecordKind.CONFIG and (change := decode_config(payload)) is not None:
        session.configs.append(change)
    elif kind == RecordKind.EVENT and (event := decode_event(payload)) is not None:
        session.events.append(event)
    elif kind == RecordKind.SOURCES and (sources := decode_sources(payload)) is not None:
        session.sources.append(sources)
    elif kind == RecordKind.STATE and (state := decode_state(payload)) is not None:
        session.states.append(state)
    elif kind == RecordKind.VOICE and (voice := decode_voice(payload)) is not None:
        session.voice.append(voice)
    elif kind == RecordKind.CONTROL and (command := decode_control(payload)) is not None:
        session.controls.append(command)
    elif kind in RESERVED_KINDS:
        name = RecordKind(kind).name.lower()
        session.skipped[name] = session.skipped.get(name, 0) + 1
    else:
        raise ValueError(f"unknown record kind code {kind}")
