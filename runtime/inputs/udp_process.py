"""A live frame source whose receiving and decoding run in a child process.

Why: in :class:`~facepuppet.runtime.inputs.udp.UdpSource` the receive thread
decodes datagrams in pure Python and needs the GIL, which the frame loop holds
through every moderngl call (a draw and ``finish()`` on llvmpipe: 10-30 ms).
Datagrams then wait in the kernel until the loop lets go (measured in a live
run on 2 cores: p50 3 ms, p99 16 ms when the machine was quiet, hundreds of ms
under load), and each hand-over of the GIL costs the loop a switch. Here a
child process (its own interpreter, its own GIL) reads and decodes, and
writes the newest frame into a shared-memory slot; the frame loop copies the
slot once per tick and nothing else in its process competes for its GIL.

Same interface as :class:`UdpSource`: ``start()``/``stop()``, ``address``,
``latest(t) -> (frame or None, stale)``, ``frames_taken``, ``watched``, ``counters``,
``last_error``, ``on_packet``. Differences:

* the receive time is always the kernel's arrival stamp on the monotonic clock
  (``SO_TIMESTAMPNS``; the child's read time where there is none): no ``clock``;
* ``on_packet`` (the recorder) runs in the *parent*: the child copies each
  accepted datagram into a shared ring (4 MiB) and
  :meth:`UdpProcessSource.deliver_packets` hands the ring's datagrams to
  ``on_packet`` when the frame loop's recording hook calls it (once a tick),
  :meth:`stop` the rest; a full ring drops and counts
  (``packets_ring_dropped``), never blocks. :meth:`latest` is a snapshot only;
* the adapter is copied into the child (pickled), so ``source.adapter.counters``
  stays at zero: read :attr:`counters`, which the child keeps current;
* :meth:`UdpProcessSource.wait_for_frame` sleeps on a pipe the child writes a
  byte to after each frame it publishes (the frame loop's draw on arrival);
* frames with more than ``MAX_WEIGHTS`` weights or ``MAX_MARKERS`` markers are
  dropped and counted (``frame_too_large``).

The slot is a seqlock: the child makes the sequence odd, writes, makes it even;
the reader copies and retries when the sequence moved (at most ``READ_TRIES``
times, then takes nothing this tick and counts ``snapshot_busy``). Names (channel
tuples, marker names, sources) go through a ring in the same memory, written
before the slot that uses them and named by their position in it, so old marker
layouts are overwritten and new ones always get in; counter names and the last
error go through a small append-only log.
Ordering relies on stores becoming visible in program order (x86-64's model).
The child's side is :mod:`~facepuppet.runtime.inputs.udp_child`.
"""

from __future__ import annotations

import json
import os
import pickle
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing import shared_memory
from typing import TYPE_CHECKING

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.udp import bind_udp, bound_address, normalise_allow
from facepuppet.runtime.inputs.udp_shared import (
    CHANNELS,
    COMPLETED,
    FLAGS,
    HAS_MARKERS,
    HAS_ROTATION,
    HAS_TRANSLATION,
    HAS_WEIGHTS,
    MARKER_NAMES,
    META_END,
    N_MARKERS,
    N_WEIGHTS,
    NAME,
    NAMES_BYTES,
    NAMES_END,
    NUMBER,
    READY,
    RECORD,
    RING_BYTES,
    RING_R,
    RING_W,
    SEQ,
    SOURCE,
    STOP,
    VALID_FOR,
    WATCHED,
    WRAP,
    SharedBlock,
    padded,
)

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import InputAdapter

READ_TRIES = 64
MAX_CACHED_NAMES = 256  # names (channel tuples, marker layouts, sources) kept here; the oldest goes first
START_TIMEOUT_S = 30.0  # a spawned interpreter importing NumPy on a loaded 2-core machine

class UdpProcessSource:
    """Frames from UDP datagrams decoded by ``adapter`` in a child process.

    Parameters
    ----------
    adapter : picklable object with ``kind``, ``default_port``, ``counters`` and
        ``handle(data, t_receive) -> Frame | None`` (see :mod:`facepuppet.runtime.inputs.kinds`)
    host : str, address to bind
    port : int or None, None for the adapter's default port, 0 for any free port
    allow : set of str or None, sender IP addresses accepted (None: all)
    on_packet : callable(data bytes, t_receive float, sender (host, port)) or None, called
        on the thread that calls :meth:`deliver_packets` / :meth:`stop`
    ring_bytes : int, size of the datagram ring for ``on_packet`` (a multiple of 16, >= 128 KiB)
    watch : str or None, an OSC address: the child counts the decoded OSC messages with exactly this
        address (bundles included) in accepted datagrams in :attr:`watched`, without shipping every
        datagram to this process as ``on_packet`` does
    """

    def __init__(self, adapter: InputAdapter, host: str = "127.0.0.1", port: int | None = None,
                 allow: set[str] | None = None, on_packet: Callable[[bytes, float, tuple], None] | None = None,
                 ring_bytes: int = RING_BYTES, watch: str | None = None) -> None:
        if ring_bytes % 16 or ring_bytes < 1 << 17:
            raise ValueError(f"UdpProcessSource ring_bytes: expected a multiple of 16 of at least {1 << 17}, "
                             f"got {ring_bytes!r}")
        self.ring_bytes = int(ring_bytes)
        self.watch = None if watch is None else str(watch)
        self.adapter = adapter
        self.host = host
        self.port = adapter.default_port if port is None else int(port)
        self.allow = normalise_allow(allow)
        self.on_packet = on_packet
        self.last_error: BaseException | None = None
        self.rcvbuf_bytes = 0
        self._own = {"snapshot_busy": 0, "internal_error": 0}
        self._stale_dropped = 0
        self._taken = 0
        self._sock: socket.socket | None = None
        self._shm: shared_memory.SharedMemory | None = None
        self._shared: SharedBlock | None = None
        self._process = None
        self._names: dict[tuple[str, int], object] = {}
        self._counter_names: dict[int, str] = {}
        self._names_pos = 0
        self._final: dict[str, int] | None = None
        self._wake: tuple[int, int] | None = None   # pipe (read, write): a byte per published frame
        self._alive: tuple[int, int] | None = None  # pipe (read: the child's, write: held here until stop)
        self._watched_final = 0

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound; the requested ones before :meth:`start`."""
        return bound_address(self._sock, self.host, self.port)

    def start(self) -> UdpProcessSource:
        """Bind (here, so a busy port raises here) and start the receiving process.

        Returns once the child runs; datagrams arriving before wait in the
        kernel buffer and keep their arrival stamps.

        Raises
        ------
        OSError
            naming host:port when the address cannot be bound.
        RuntimeError
            when the child does not start within START_TIMEOUT_S.
        """
        if self._process is not None:
            raise RuntimeError("UdpProcessSource.start: already started")
        sock, self.rcvbuf_bytes = bind_udp(self.host, self.port, self.adapter.kind, stamps=True)
        self._sock = sock
        self._shm = shared_memory.SharedMemory(create=True, size=SharedBlock.size(self.ring_bytes))
        self._shared = SharedBlock(self._shm, self.ring_bytes)
        self._names, self._counter_names, self._names_pos, self._final = {}, {}, 0, None
        self._taken = self._stale_dropped = 0
        self._wake = os.pipe()
        for fd in self._wake:
            os.set_blocking(fd, False)   # the child never waits on a full pipe; the parent drains
        self._alive = os.pipe()   # only this process holds the write end: its death closes it (the child leaves)
        # PR_SET_PDEATHSIG follows the starting *thread*: asked for only from the main thread
        deathsig = threading.current_thread() is threading.main_thread()
        # A fresh interpreter (not fork: this process may hold a GL context and threads; not
        # multiprocessing's spawn: it re-imports the caller's __main__), given the socket by descriptor.
        self._process = subprocess.Popen(
            [sys.executable, "-c", "from facepuppet.runtime.inputs.udp_child import child_main; child_main()"],
            stdin=subprocess.PIPE, pass_fds=(sock.fileno(), self._wake[1], self._alive[0]))
        os.close(self._alive[0])
        try:
            self._process.stdin.write(pickle.dumps((self._shm.name, self.ring_bytes, sock.fileno(), sock.family,
                                                    self.adapter, self.allow, self.on_packet is not None,
                                                    os.getpid(), self.watch,
                                                    self._wake[1], self._alive[0], deathsig)))
            self._process.stdin.close()
        except (OSError, pickle.PicklingError) as exc:
            self.stop()
            raise RuntimeError(f"UdpProcessSource: cannot hand the adapter to the receiving process: {exc}") from exc
        end = time.monotonic() + START_TIMEOUT_S
        while not self._shared.ctl[READY]:
            if self._process.poll() is not None or time.monotonic() > end:
                code = self._process.poll()
                self.stop()
                raise RuntimeError(f"UdpProcessSource: the receiving process did not start (exit code {code})")
            time.sleep(0.005)
        return self

    def stop(self) -> None:
        """Stop the child (within about POLL_TIMEOUT_S), hand on the ring's last datagrams, free everything."""
        shared = self._shared
        if self._process is not None:
            if shared is not None:
                shared.ctl[STOP] = 1
            if self._alive is not None:
                os.close(self._alive[1])  # the child sees the pipe close at once
                self._alive = None
            try:
                self._process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait(timeout=5.0)
            self._process = None
        if shared is not None:
            self.deliver_packets()
            self._watched_final = int(shared.ctl[WATCHED])
            self._final = self._read_counters()
            shared.release()
            self._shared = None
        if self._shm is not None:
            self._shm.close()
            self._shm.unlink()
            self._shm = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._wake is not None:
            for fd in self._wake:
                os.close(fd)
            self._wake = None
        if self._alive is not None:
            os.close(self._alive[1])
            self._alive = None

    def __enter__(self) -> UdpProcessSource:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def watched(self) -> int:
        """OSC messages to ``watch`` accepted so far (a count that only grows)."""
        shared = self._shared
        return int(shared.ctl[WATCHED]) if shared is not None else self._watched_final

    @property
    def frames_taken(self) -> int:
        """Frames completed up to the newest one :meth:`latest` handed out (0 before any)."""
        return self._taken

    def pending(self) -> bool:
        """A frame not yet taken is there (:meth:`latest` would hand it out)."""
        shared = self._shared
        return shared is not None and shared.ctl[COMPLETED] != self._taken

    @property
    def wake_fd(self) -> int | None:
        """The read end of the pipe the child writes a byte to per published frame (None before start);
        non-blocking: :class:`~facepuppet.runtime.inputs.arrival.ArrivalWaiter` drains it and selects on it."""
        return None if self._wake is None else self._wake[0]

    def wait_for_frame(self, timeout_s: float) -> bool:
        """Sleep until a frame not yet taken is there (True) or ``timeout_s`` passes (False)."""
        shared, wake = self._shared, self._wake
        if shared is None or wake is None:
            time.sleep(max(0.0, timeout_s))
            return False
        try:                                  # bytes of frames already taken (or about to be: checked next)
            os.read(wake[0], 1 << 16)
        except BlockingIOError:
            pass
        if shared.ctl[COMPLETED] != self._taken:
            return True
        if timeout_s <= 0:
            return False
        return bool(select.select([wake[0]], [], [], timeout_s)[0])

    def latest(self, t: float | None = None) -> tuple[Frame | None, int]:
        """(newest frame not yet taken or None, frames overwritten unseen since the last call).

        A snapshot: no callbacks (:meth:`deliver_packets` hands datagrams on). ``t`` is accepted for the
        source interface and ignored.
        """
        shared = self._shared
        if shared is None:
            return None, 0
        ctl = shared.ctl
        copy = None
        for _ in range(READ_TRIES):
            seq = ctl[SEQ]
            if seq & 1:
                continue
            completed = ctl[COMPLETED]
            if completed == self._taken:
                break
            copy = self._copy_slot(shared)
            if ctl[SEQ] == seq:
                break
            copy = None
        else:
            self._own["snapshot_busy"] += 1
        if copy is None:
            return None, 0
        try:
            frame = self._frame(copy)
        except Exception as exc:  # a slot naming something the log does not hold: count, never raise
            self._own["internal_error"] += 1
            self.last_error = exc
            return None, 0
        stale = completed - self._taken - 1
        self._taken = completed
        self._stale_dropped += stale
        return frame, stale

    @staticmethod
    def _copy_slot(shared: SharedBlock) -> tuple:
        ctl = shared.ctl
        flags, n_weights, n_markers = ctl[FLAGS], ctl[N_WEIGHTS], ctl[N_MARKERS]
        weights = shared.weights[:n_weights].copy() if flags & HAS_WEIGHTS else None
        markers = shared.markers[:3 * n_markers].reshape(n_markers, 3).copy() if flags & HAS_MARKERS else None
        return (flags, ctl[CHANNELS], ctl[MARKER_NAMES], ctl[SOURCE], ctl[NUMBER], shared.times.copy(),
                shared.pose.copy(), weights, markers)

    def _frame(self, copy: tuple) -> Frame:
        flags, channels, marker_names, source, number, times, pose, weights, markers = copy
        name = self._name
        return Frame(t=times[0], source=name("source", source), channels=name("channels", channels),
                     weights=weights, head_rotation=pose[:4] if flags & HAS_ROTATION else None,
                     head_translation=pose[4:7] if flags & HAS_TRANSLATION else None, audio_level=times[2],
                     markers=markers, marker_names=name("markers", marker_names), t_sender=times[1],
                     number=number)

    def _name(self, kind: str, i: int):
        """The name (channel tuple, marker names, source) the child wrote at ring position ``i``.

        Positions are never reused, so what is cached stays right; a record the child may have
        overwritten since (a flood of new layouts between the frame and this read) raises.
        """
        if i == -1:
            return None
        key = (kind, i)
        value = self._names.get(key)
        if value is not None:
            return value
        shared = self._shared
        names, ctl = shared.names, shared.ctl
        if i < 0 or i >= ctl[NAMES_END] or ctl[NAMES_END] - i > VALID_FOR:
            raise RuntimeError(f"names ring: record {i} is gone (written up to {ctl[NAMES_END]})")
        p = i % NAMES_BYTES
        (n,) = NAME.unpack_from(names, p)
        payload = bytes(names[p + NAME.size:p + NAME.size + n]) if p + NAME.size + n <= NAMES_BYTES else b""
        if ctl[NAMES_END] - i > VALID_FOR:  # overwritten while we copied
            raise RuntimeError(f"names ring: record {i} was overwritten while read")
        found_kind, value = json.loads(payload)
        if found_kind != kind:
            raise RuntimeError(f"names ring: record {i} is {found_kind!r}, expected {kind!r}")
        value = tuple(value) if isinstance(value, list) else value
        if len(self._names) >= MAX_CACHED_NAMES:
            del self._names[next(iter(self._names))]  # the oldest
        self._names[key] = value
        return value

    def _read_names(self) -> None:
        """Take the counter names and errors the child logged since the last read."""
        shared = self._shared
        end = shared.ctl[META_END]
        while self._names_pos < end:
            (n,) = NAME.unpack_from(shared.meta, self._names_pos)
            kind, key, value = json.loads(bytes(shared.meta[self._names_pos + 4:self._names_pos + 4 + n]))
            self._names_pos += 4 + n
            if kind == "counter":
                self._counter_names[key] = value
            elif kind == "error":
                self.last_error = RuntimeError(value)

    def deliver_packets(self) -> None:
        """Hand every datagram in the ring to ``on_packet`` (its errors are counted, never raised).

        The child rings a datagram before it publishes its frame, so after :meth:`latest` every
        datagram behind the frame taken is in the ring: called after the snapshot (the recording
        hook does), they reach the recorder before that tick's TICK record.
        """
        shared, on_packet = self._shared, self.on_packet
        if shared is None or on_packet is None:
            return
        ctl, ring, size = shared.ctl, shared.ring, shared.ring_bytes
        r, w = ctl[RING_R], ctl[RING_W]
        while r < w:
            p = r % size
            length, t, port, host_len = RECORD.unpack_from(ring, p)
            if length == WRAP:
                r += size - p
                continue
            start = p + RECORD.size
            host = bytes(ring[start:start + host_len]).decode("ascii")
            data = bytes(ring[start + host_len:start + host_len + length])
            r += padded(RECORD.size + host_len + length)
            try:
                on_packet(data, t, (host, port))
            except Exception as exc:
                self._own["internal_error"] += 1
                self.last_error = exc
        ctl[RING_R] = r

    def _read_counters(self) -> dict[str, int]:
        self._read_names()
        values = self._shared.counters
        return {name: values[i] for i, name in self._counter_names.items()}

    @property
    def counters(self) -> dict[str, int]:
        """The child's counters (adapter's merged with packets, filtered_sender, internal_error,
        waited_over_1ms, frame_too_large, packets_ring_dropped, names_full (the counter-name and error log
        is full), names_too_large (one name record over MAX_NAME_RECORD)) plus snapshot_busy,
        stale_dropped and rcvbuf_bytes; ``internal_error`` adds both processes'."""
        merged = dict(self._final) if self._shared is None and self._final is not None else (
            self._read_counters() if self._shared is not None else {})
        for name, value in self._own.items():
            merged[name] = merged.get(name, 0) + value
        merged["stale_dropped"] = self._stale_dropped
        merged["rcvbuf_bytes"] = self.rcvbuf_bytes
        return merged
