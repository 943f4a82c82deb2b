"""``--record FILE``: every received datagram and the audio levels, appended to a session file.

The UDP receive thread calls :meth:`PacketRecorder.put` for each accepted
datagram; ``put`` only appends a tuple to a bounded deque (never blocks, never
raises: when the writer falls behind by ``capacity`` records the record is
dropped and counted). A writer thread takes them off and appends one PACKET
record each to a :class:`~facepuppet.runtime.recording.session.SessionWriter` (one
``os.write`` per record, so a ``kill -9`` loses at most the record being
written). Replaying the file re-decodes the packets with a fresh adapter of the
recorded input kind (:func:`~facepuppet.runtime.recording.replay_source.open_recording`),
which gives back the frame stream the live run saw.

A write that fails (disk full, the file-size limit) ends the writer thread without a traceback: the file
is cut back to its last whole record, :attr:`PacketRecorder.failure` says what it keeps, and
``on_failure`` is told (``run`` then stops: a recording that cannot be written must not be taken for one
that was). What is queued after that is dropped.
"""

from __future__ import annotations

import collections
import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from facepuppet.runtime.recording.records import (
    RecordKind,
    encode_audio,
    encode_config,
    encode_control,
    encode_event,
    encode_packet_record,
    encode_sources,
    encode_state,
    encode_tick,
    encode_voice,
)
from facepuppet.runtime.recording.session import SessionWriter

if TYPE_CHECKING:
    import os

    import numpy as np

logger = logging.getLogger(__name__)


class PacketRecorder:
    """Record datagrams and audio levels without blocking their producers.

    Parameters
    ----------
    path : str or Path, the session file to create (refuses to overwrite unless ``overwrite``)
    kind : str, the input kind of the packets (stored in each PACKET record)
    info : dict, JSON-serialisable facts for the header (character, listen address, ...)
    capacity : int, records that may wait for the writer before new ones are dropped
    fsync_every_s : float or None, see :class:`SessionWriter`

    Attributes
    ----------
    counters : dict: ``packets_recorded``, ``audio_recorded``, ``ticks_recorded``, ``configs_recorded``,
        ``events_recorded``, ``record_dropped`` (queue full)
    failure : str or None, why the file stopped growing and what it keeps (None while every write succeeded)
    on_failure : callable(PacketRecorder) or None, called once (on the writer thread, or in :meth:`close`)
        when a write fails
    """

    def __init__(self, path: str | os.PathLike, kind: str, info: dict | None = None, capacity: int = 8192,
                 fsync_every_s: float | None = 1.0, overwrite: bool = False) -> None:
        self.kind = kind
        self.capacity = int(capacity)
        self.writer = SessionWriter(path, info={"recording": "live packets", "input": kind, **(info or {})},
                                    fsync_every_s=fsync_every_s, overwrite=overwrite)
        self.path = self.writer.path
        self.counters = {"packets_recorded": 0, "audio_recorded": 0, "ticks_recorded": 0, "configs_recorded": 0,
                         "events_recorded": 0, "record_dropped": 0}
        self.failure: str | None = None
        self.on_failure: Callable[[PacketRecorder], None] | None = None
        self._ticks_written: tuple[float, float] | None = None  # the first and the newest TICK time written
        self._queue: collections.deque = collections.deque()
        self._wake = threading.Event()
        self._stopping = False
        self._thread = threading.Thread(target=self._drain, name="facepuppet-recorder", daemon=True)
        self._thread.start()

    def put(self, data: bytes, t_receive: float, sender: tuple | None = None) -> None:
        """Queue one datagram (receive thread; an ``on_packet`` callback). Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.PACKET, t_receive, data))  # deque.append is atomic
        self._wake.set()

    def put_audio(self, t: float, level_db: float) -> None:
        """Queue one audio level (frame-loop thread). Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.AUDIO, t, level_db))
        self._wake.set()

    def put_voice(self, t: float, values: np.ndarray) -> None:
        """Queue one tick's voice channels (frame-loop thread; a copy is queued). Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.VOICE, t, bytes(encode_voice(t, values))))
        self._wake.set()

    def put_tick(self, k: int, t: float, frames: int, t_clock: float) -> None:
        """Queue one TICK record (frame-loop thread; see :class:`~facepuppet.runtime.recording.records.Tick`).
        Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.TICK, t, (k, frames, t_clock)))
        self._wake.set()

    def put_config(self, t: float, text: str) -> None:
        """Queue one CONFIG record: the config (TOML text) that took effect at tick time ``t``. Never blocks;
        a config change is not dropped for a full queue (it is rare, and a replay needs every one)."""
        self._queue.append((RecordKind.CONFIG, t, text))
        self._wake.set()

    def put_state(self, t: float, text: str) -> None:
        """Queue the STATE record of a recording started mid-run: the filter stage's state (JSON text) at tick
        time ``t``. Never blocks; not dropped for a full queue (one per recording)."""
        self._queue.append((RecordKind.STATE, t, text))
        self._wake.set()

    def tagged(self, label: str) -> Callable[..., None]:
        """An ``on_packet`` callable for another input of the run: its datagrams are recorded under ``label``
        (a mix source name such as ``openseeface`` or ``vmc#2``) instead of this recorder's kind."""
        def put(data: bytes, t_receive: float, sender: tuple | None = None) -> None:
            if len(self._queue) >= self.capacity:
                self.counters["record_dropped"] += 1
                return
            self._queue.append((RecordKind.PACKET, t_receive, (label, data)))
            self._wake.set()
        return put

    def put_control(self, t: float, command: dict) -> None:
        """Queue one CONTROL record: a control command applied at tick time ``t``. Never blocks; not dropped for a
        full queue (a replay needs every one, and the servers bound their rate)."""
        self._queue.append((RecordKind.CONTROL, t, command))
        self._wake.set()

    def put_sources(self, k: int, frames: tuple[int, ...]) -> None:
        """Queue one SOURCES record: frames each mix source had completed at tick ``k``. Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.SOURCES, k, tuple(frames)))
        self._wake.set()

    def put_event(self, t: float, found: bool) -> None:
        """Queue one EVENT record, tracking lost / found (frame-loop thread: a pipeline listener). Never blocks."""
        if len(self._queue) >= self.capacity:
            self.counters["record_dropped"] += 1
            return
        self._queue.append((RecordKind.EVENT, t, bool(found)))
        self._wake.set()

    def _drain(self) -> None:
        q = self._queue
        while True:
            self._wake.wait(0.05)
            self._wake.clear()
            try:
                while q:
                    self._write(*q.popleft())
            except (OSError, ValueError) as exc:  # disk full, file-size limit, a record over the format's size
                q.clear()
                self._fail(exc)
                return
            if self._stopping and not q:
                return

    def _write(self, kind: RecordKind, t: float, value) -> None:
        write = self.writer.write_record
        if kind == RecordKind.PACKET:
            label, data = value if isinstance(value, tuple) else (self.kind, value)
            write(kind, encode_packet_record(t, label, data))
            self.counters["packets_recorded"] += 1
        elif kind == RecordKind.CONFIG:
            write(kind, encode_config(t, value))
            self.counters["configs_recorded"] += 1
        elif kind == RecordKind.STATE:
            write(kind, encode_state(t, value))
        elif kind == RecordKind.TICK:
            write(kind, encode_tick(value[0], t, value[1], value[2]))
            self.counters["ticks_recorded"] += 1
            self._ticks_written = (t if self._ticks_written is None else self._ticks_written[0], t)
        elif kind == RecordKind.SOURCES:
            write(kind, encode_sources(t, value))
        elif kind == RecordKind.CONTROL:
            write(kind, encode_control(t, value))
        elif kind == RecordKind.EVENT:
            write(kind, encode_event(t, value))
            self.counters["events_recorded"] += 1
        elif kind == RecordKind.VOICE:
            write(kind, value)
        else:
            write(kind, encode_audio(t, value))
            self.counters["audio_recorded"] += 1

    def _fail(self, exc: BaseException) -> None:
        """Say why the file stopped growing and what it keeps; tell ``on_failure`` (once)."""
        if self.failure is not None:
            return
        c, ticks = self.counters, self._ticks_written
        kept = (f"{c['ticks_recorded']} ticks ({ticks[1] - ticks[0]:.2f} s of the run), " if ticks else "") + \
            f"{c['packets_recorded']} packets"
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        self.failure = (f"{self.path}: the recording stopped: a write failed ({reason}); the file keeps its first "
                        f"{self.writer.n_records} records ({self.writer.size} bytes: {kept}) and reads and "
                        "replays up to there")
        if self.on_failure is not None:
            try:
                self.on_failure(self)
            except Exception:  # the writer thread never raises
                logger.exception("recorder: on_failure")

    def close(self) -> None:
        """Write what is queued, fsync and close the file (a failure to is kept in :attr:`failure`)."""
        if self._thread.is_alive():
            self._stopping = True
            self._wake.set()
            self._thread.join()
        try:
            self.writer.close()
        except OSError as exc:
            self._fail(exc)

    def __enter__(self) -> PacketRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
