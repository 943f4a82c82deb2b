"""A live frame source whose receiving and decoding run in a child process.

Why: in :class:`~facepuppet.runtime.udp_source.UdpSource` the receive thread
decodes datagrams in pure Python and needs the GIL, which the frame loop holds
through every moderngl call (a draw and ``finish()`` on llvmpipe: 10-30 ms).
Datagrams then wait in the kernel until the loop lets go (measured in a live
run on 2 cores: p50 3 ms, p99 16 ms when the machine was quiet, hundreds of ms
under load), and each hand-over of the GIL costs the loop a switch. Here a
child process (its own interpreter, its own GIL) reads and decodes, and
writes the newest frame into a shared-memory slot; the frame loop copies the
slot once per tick and nothing else in its process competes for its GIL.

Same interface as :class:`UdpSource`: ``start()``/``stop()``, ``address``,
``latest(t) -> (frame or None, stale)``, ``frames_taken``, ``counters``,
``last_error``, ``on_packet``. Differences:

* the receive time is always the kernel's arrival stamp on the monotonic clock
  (``SO_TIMESTAMPNS``; the child's read time where there is none): no ``clock``;
* ``on_packet`` (the recorder, the calibrate message) runs in the *parent*: the
  child copies each accepted datagram into a shared ring (4 MiB) and
  :meth:`UdpProcessSource.latest` hands the ring's datagrams to ``on_packet``
  every tick, then :meth:`stop` the rest; a full ring drops and counts
  (``packets_ring_dropped``), never blocks;
* the adapter is copied into the child (pickled), so ``source.adapter.counters``
  stays at zero: read :attr:`counters`, which the child keeps current;
* frames with more than ``MAX_WEIGHTS`` weights or ``MAX_MARKERS`` markers are
  dropped and counted (``frame_too_large``).

The slot is a seqlock: the child makes the sequence odd, writes, makes it even;
the reader copies and retries when the sequence moved (at most ``READ_TRIES``
times, then takes nothing this tick and counts ``snapshot_busy``). Names (channel
tuples, marker names, sources, counter names, the last error) go through an
append-only log in the same memory, written before the slot that uses them.
Ordering relies on stores becoming visible in program order (x86-64's model).
"""

from __future__ import annotations

import json
import os
import pickle
import socket
import struct
import subprocess
import sys
import time
from multiprocessing import shared_memory

import numpy as np

from .frames import Frame
from .udp_source import LATE_READ_S, POLL_TIMEOUT_S, SOCKET_BUFFER, enable_kernel_stamps, receive_stamped

MAX_WEIGHTS = 1024
MAX_MARKERS = 2048
MAX_COUNTERS = 64
NAMES_BYTES = 1 << 20
RING_BYTES = 4 << 20
READ_TRIES = 64
MAX_ERRORS_LOGGED = 100
START_TIMEOUT_S = 30.0  # a spawned interpreter importing NumPy on a loaded 2-core machine
# control words (int64)
SEQ, COMPLETED, NAMES_END, RING_W, RING_R, READY, STOP, N_WEIGHTS, N_MARKERS, CHANNELS, MARKER_NAMES, SOURCE, \
    NUMBER, FLAGS, N_CTL = range(15)
HAS_WEIGHTS, HAS_MARKERS, HAS_ROTATION, HAS_TRANSLATION = 1, 2, 4, 8
_RECORD = struct.Struct("<IdHBx")  # datagram length, receive time, sender port, sender host length (16 bytes)
_WRAP = 0xFFFFFFFF
_NAME = struct.Struct("<I")


class _Shared:
    """Views of the shared block: control words, times, pose, counters, weights, markers, name log, ring."""

    def __init__(self, shm: shared_memory.SharedMemory, ring_bytes: int):
        self.shm = shm
        self.ring_bytes = ring_bytes
        buf = shm.buf
        o = 0

        def take(n_bytes):
            nonlocal o
            view = buf[o:o + n_bytes]
            o += n_bytes
            return view

        self.ctl = take(8 * N_CTL).cast("q")
        self.times = np.frombuffer(take(8 * 3), dtype=np.float64)  # t, t_sender, audio_level
        self.pose = np.frombuffer(take(4 * 8), dtype=np.float32)  # rotation (4), translation (3), pad
        self.counters = take(8 * MAX_COUNTERS).cast("q")
        self.weights = np.frombuffer(take(4 * MAX_WEIGHTS), dtype=np.float32)
        self.markers = np.frombuffer(take(4 * 3 * MAX_MARKERS), dtype=np.float32)
        self.names = take(NAMES_BYTES)
        self.ring = take(ring_bytes)

    @staticmethod
    def size(ring_bytes: int) -> int:
        return 8 * N_CTL + 24 + 32 + 8 * MAX_COUNTERS + 4 * MAX_WEIGHTS + 12 * MAX_MARKERS + NAMES_BYTES + ring_bytes

    def release(self) -> None:
        for name in ("ctl", "counters", "names", "ring"):
            getattr(self, name).release()
        self.times = self.pose = self.weights = self.markers = None


class UdpProcessSource:
    """Frames from UDP datagrams decoded by ``adapter`` in a child process.

    Parameters
    ----------
    adapter : picklable object with ``kind``, ``default_port``, ``counters`` and
        ``handle(data, t_receive) -> Frame | None`` (see :mod:`.input_kinds`)
    host : str, address to bind
    port : int or None, None for the adapter's default port, 0 for any free port
    allow : set of str or None, sender IP addresses accepted (None: all)
    on_packet : callable(data bytes, t_receive float, sender (host, port)) or None, called
        on the thread that calls :meth:`latest` / :meth:`stop`
    ring_bytes : int, size of the datagram ring for ``on_packet`` (a multiple of 16, >= 128 KiB)
    """

    def __init__(self, adapter, host: str = "127.0.0.1", port: int | None = None,
                 allow: set[str] | None = None, on_packet=None, ring_bytes: int = RING_BYTES):
        if ring_bytes % 16 or ring_bytes < 1 << 17:
            raise ValueError(f"UdpProcessSource ring_bytes: expected a multiple of 16 of at least {1 << 17}, "
                             f"got {ring_bytes!r}")
        self.ring_bytes = int(ring_bytes)
        self.adapter = adapter
        self.host = host
        self.port = adapter.default_port if port is None else int(port)
        self.allow = None if allow is None else frozenset(allow)
        self.on_packet = on_packet
        self.last_error: BaseException | None = None
        self.rcvbuf_bytes = 0
        self._own = {"snapshot_busy": 0, "internal_error": 0}
        self._stale_dropped = 0
        self._taken = 0
        self._sock: socket.socket | None = None
        self._shm: shared_memory.SharedMemory | None = None
        self._shared: _Shared | None = None
        self._process = None
        self._names: dict[tuple[str, int], object] = {}
        self._counter_names: dict[int, str] = {}
        self._names_pos = 0
        self._final: dict[str, int] | None = None

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound; the requested ones before :meth:`start`."""
        if self._sock is None:
            return self.host, self.port
        host, port = self._sock.getsockname()[:2]
        return host, port

    def start(self) -> "UdpProcessSource":
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
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER)
        except OSError:
            pass
        self.rcvbuf_bytes = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        enable_kernel_stamps(sock)  # before bind: the first datagram is stamped too
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise OSError(exc.errno, f"cannot listen for {self.adapter.kind} input on "
                                     f"{self.host}:{self.port}: {exc.strerror or exc} "
                                     f"(is another program using this port?)") from exc
        self._sock = sock
        self._shm = shared_memory.SharedMemory(create=True, size=_Shared.size(self.ring_bytes))
        self._shared = _Shared(self._shm, self.ring_bytes)
        self._names, self._counter_names, self._names_pos, self._final = {}, {}, 0, None
        self._taken = self._stale_dropped = 0
        # A fresh interpreter (not fork: this process may hold a GL context and threads; not
        # multiprocessing's spawn: it re-imports the caller's __main__), given the socket by descriptor.
        self._process = subprocess.Popen(
            [sys.executable, "-c", "from facepuppet.runtime.udp_process import child_main; child_main()"],
            stdin=subprocess.PIPE, pass_fds=(sock.fileno(),))
        try:
            self._process.stdin.write(pickle.dumps((self._shm.name, self.ring_bytes, sock.fileno(), sock.family,
                                                    self.adapter, self.allow, self.on_packet is not None,
                                                    os.getpid())))
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
            try:
                self._process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait(timeout=5.0)
            self._process = None
        if shared is not None:
            self._drain_ring()
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

    def __enter__(self) -> "UdpProcessSource":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def frames_taken(self) -> int:
        """Frames completed up to the newest one :meth:`latest` handed out (0 before any)."""
        return self._taken

    def latest(self, t: float | None = None) -> tuple[Frame | None, int]:
        """(newest frame not yet taken or None, frames overwritten unseen since the last call).

        Hands the datagrams received since the last call to ``on_packet`` first.
        ``t`` is accepted for the source interface and ignored.
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
        # after the slot: the child rings a datagram before it publishes its frame, so every datagram
        # behind the frame taken reaches on_packet (the recorder) before this tick's TICK record
        if self.on_packet is not None:
            self._drain_ring()
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
    def _copy_slot(shared: _Shared) -> tuple:
        ctl = shared.ctl
        flags, n_weights, n_markers = ctl[FLAGS], ctl[N_WEIGHTS], ctl[N_MARKERS]
        weights = shared.weights[:n_weights].copy() if flags & HAS_WEIGHTS else None
        markers = shared.markers[:3 * n_markers].reshape(n_markers, 3).copy() if flags & HAS_MARKERS else None
        return (flags, ctl[CHANNELS], ctl[MARKER_NAMES], ctl[SOURCE], ctl[NUMBER], shared.times.copy(),
                shared.pose.copy(), weights, markers)

    def _frame(self, copy: tuple) -> Frame:
        flags, channels, marker_names, source, number, times, pose, weights, markers = copy
        names = self._names
        if (("channels", channels) not in names or ("markers", marker_names) not in names
                or ("source", source) not in names):
            self._read_names()
        return Frame(t=times[0], source=names[("source", source)], channels=names[("channels", channels)],
                     weights=weights, head_rotation=pose[:4] if flags & HAS_ROTATION else None,
                     head_translation=pose[4:7] if flags & HAS_TRANSLATION else None, audio_level=times[2],
                     markers=markers, marker_names=names[("markers", marker_names)], t_sender=times[1],
                     number=number)

    def _read_names(self) -> None:
        """Take the log's records written since the last read."""
        shared = self._shared
        end = shared.ctl[NAMES_END]
        while self._names_pos < end:
            (n,) = _NAME.unpack_from(shared.names, self._names_pos)
            kind, key, value = json.loads(bytes(shared.names[self._names_pos + 4:self._names_pos + 4 + n]))
            self._names_pos += 4 + n
            if kind == "counter":
                self._counter_names[key] = value
            elif kind == "error":
                self.last_error = RuntimeError(value)
            else:
                self._names[(kind, key)] = tuple(value) if isinstance(value, list) else value
        self._names.setdefault(("channels", -1), None)
        self._names.setdefault(("markers", -1), None)

    def _drain_ring(self) -> None:
        """Hand every datagram in the ring to ``on_packet`` (its errors are counted, never raised)."""
        shared, on_packet = self._shared, self.on_packet
        if shared is None or on_packet is None:
            return
        ctl, ring, size = shared.ctl, shared.ring, shared.ring_bytes
        r, w = ctl[RING_R], ctl[RING_W]
        while r < w:
            p = r % size
            length, t, port, host_len = _RECORD.unpack_from(ring, p)
            if length == _WRAP:
                r += size - p
                continue
            start = p + _RECORD.size
            host = bytes(ring[start:start + host_len]).decode("ascii")
            data = bytes(ring[start + host_len:start + host_len + length])
            r += _padded(_RECORD.size + host_len + length)
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
        waited_over_1ms, frame_too_large, packets_ring_dropped, names_full) plus snapshot_busy,
        stale_dropped and rcvbuf_bytes; ``internal_error`` adds both processes'."""
        merged = dict(self._final) if self._shared is None and self._final is not None else (
            self._read_counters() if self._shared is not None else {})
        for name, value in self._own.items():
            merged[name] = merged.get(name, 0) + value
        merged["stale_dropped"] = self._stale_dropped
        merged["rcvbuf_bytes"] = self.rcvbuf_bytes
        return merged


def _padded(n: int) -> int:
    return (n + 15) & ~15


class _Writer:
    """The child's side: names log, counters, slot, ring."""

    def __init__(self, shared: _Shared, adapter):
        self.shared, self.adapter = shared, adapter
        self.ids: dict[tuple[str, object], int] = {}
        self.counter_index: dict[str, int] = {}
        self.errors_logged = 0
        self.own = {"packets": 0, "filtered_sender": 0, "internal_error": 0, "waited_over_1ms": 0,
                    "frame_too_large": 0, "packets_ring_dropped": 0, "names_full": 0}

    def log(self, kind: str, key, value) -> bool:
        """Append one name record; False (counted) when the log is full."""
        payload = json.dumps([kind, key, value]).encode()
        ctl, pos = self.shared.ctl, self.shared.ctl[NAMES_END]
        if pos + 4 + len(payload) > NAMES_BYTES:
            self.own["names_full"] += 1
            return False
        _NAME.pack_into(self.shared.names, pos, len(payload))
        self.shared.names[pos + 4:pos + 4 + len(payload)] = payload
        ctl[NAMES_END] = pos + 4 + len(payload)  # published after the bytes
        return True

    def error(self, exc: BaseException) -> None:
        """Log an error for ``last_error`` (the first MAX_ERRORS_LOGGED only: the log must keep room for names)."""
        if self.errors_logged < MAX_ERRORS_LOGGED:
            self.errors_logged += 1
            self.log("error", 0, repr(exc)[:500])

    def name_id(self, kind: str, value) -> int | None:
        if value is None:
            return -1
        key = (kind, value)
        i = self.ids.get(key)
        if i is None:
            i = len(self.ids)
            if not self.log(kind, i, list(value) if isinstance(value, tuple) else value):
                return None
            self.ids[key] = i
        return i

    def publish_counters(self) -> None:
        merged = dict(self.adapter.counters)
        for name, value in self.own.items():
            merged[name] = merged.get(name, 0) + value
        index, values = self.counter_index, self.shared.counters
        for name, value in merged.items():
            i = index.get(name)
            if i is None:
                if len(index) >= MAX_COUNTERS or not self.log("counter", len(index), name):
                    continue
                i = index[name] = len(index)
            values[i] = int(value)

    def publish(self, frame: Frame) -> None:
        """Write ``frame`` into the slot (seqlock)."""
        n_weights = 0 if frame.weights is None else len(frame.weights)
        n_markers = 0 if frame.markers is None else len(frame.markers)
        if n_weights > MAX_WEIGHTS or n_markers > MAX_MARKERS:
            self.own["frame_too_large"] += 1
            return
        ids = (self.name_id("channels", frame.channels), self.name_id("markers", frame.marker_names),
               self.name_id("source", frame.source))
        if None in ids:
            return
        flags = ((HAS_WEIGHTS if frame.weights is not None else 0) | (HAS_MARKERS if frame.markers is not None else 0)
                 | (HAS_ROTATION if frame.head_rotation is not None else 0)
                 | (HAS_TRANSLATION if frame.head_translation is not None else 0))
        shared = self.shared
        ctl = shared.ctl
        seq = ctl[SEQ]
        ctl[SEQ] = seq + 1  # odd: being written
        ctl[FLAGS], ctl[N_WEIGHTS], ctl[N_MARKERS] = flags, n_weights, n_markers
        ctl[CHANNELS], ctl[MARKER_NAMES], ctl[SOURCE], ctl[NUMBER] = (*ids, int(frame.number))
        shared.times[:] = (frame.t, frame.t_sender, frame.audio_level)
        if frame.head_rotation is not None:
            shared.pose[:4] = frame.head_rotation
        if frame.head_translation is not None:
            shared.pose[4:7] = frame.head_translation
        if n_weights:
            shared.weights[:n_weights] = frame.weights
        if n_markers:
            shared.markers[:3 * n_markers] = frame.markers.reshape(-1)
        ctl[COMPLETED] += 1
        ctl[SEQ] = seq + 2

    def put_packet(self, data: bytes, t: float, sender) -> None:
        """Copy one datagram into the ring for the parent's ``on_packet``; drop and count when full."""
        ctl, ring, size = self.shared.ctl, self.shared.ring, self.shared.ring_bytes
        host = str(sender[0]).encode("ascii", "replace")[:255]
        n = _padded(_RECORD.size + len(host) + len(data))
        w = ctl[RING_W]
        free = size - (w - ctl[RING_R])
        p = w % size
        gap = size - p if p + n > size else 0  # the record must be contiguous: wrap to the start
        if gap + n > free:
            self.own["packets_ring_dropped"] += 1
            return
        if gap:
            _RECORD.pack_into(ring, p, _WRAP, 0.0, 0, 0)
            w, p = w + gap, 0
        _RECORD.pack_into(ring, p, len(data), t, int(sender[1]) & 0xFFFF, len(host))
        start = p + _RECORD.size
        ring[start:start + len(host)] = host
        ring[start + len(host):start + len(host) + len(data)] = data
        ctl[RING_W] = w + n  # published after the bytes


def child_main() -> None:
    """Entry point of the receiving process: its arguments come pickled on stdin."""
    shm_name, ring_bytes, fd, family, adapter, allow, want_packets, parent_pid = pickle.load(sys.stdin.buffer)
    _child(shm_name, ring_bytes, socket.socket(family, socket.SOCK_DGRAM, fileno=fd), adapter, allow, want_packets,
           parent_pid)


def _child(shm_name: str, ring_bytes: int, sock: socket.socket, adapter, allow, want_packets: bool,
           parent_pid: int) -> None:
    """The receiving process: read, stamp, filter, copy for on_packet, decode, publish; never raises."""
    shm = shared_memory.SharedMemory(name=shm_name)
    try:  # the parent owns (and unlinks) the block: this process must not have it tracked as its own
        from multiprocessing import resource_tracker

        resource_tracker.unregister(shm._name, "shared_memory")
    except Exception:
        pass
    shared = _Shared(shm, ring_bytes)
    writer = _Writer(shared, adapter)
    own, ctl, handle = writer.own, shared.ctl, adapter.handle
    stamped = enable_kernel_stamps(sock)
    sock.settimeout(POLL_TIMEOUT_S)
    writer.publish_counters()
    ctl[READY] = 1
    try:
        while not ctl[STOP]:
            try:
                if stamped:
                    data, sender, t, t_read = receive_stamped(sock)
                    if t_read - t > LATE_READ_S:
                        own["waited_over_1ms"] += 1
                else:
                    data, sender = sock.recvfrom(65536)
                    t = time.monotonic()
            except (socket.timeout, BlockingIOError, InterruptedError):
                if os.getppid() != parent_pid:  # the parent is gone
                    break
                continue
            except OSError as exc:
                own["internal_error"] += 1
                writer.error(exc)
                time.sleep(POLL_TIMEOUT_S)
                continue
            try:
                own["packets"] += 1
                if allow is not None and sender[0] not in allow:
                    own["filtered_sender"] += 1
                else:
                    if want_packets:
                        writer.put_packet(data, t, sender)
                    frame = handle(data, t)
                    if frame is not None:
                        writer.publish(frame)
            except Exception as exc:  # nothing escapes
                own["internal_error"] += 1
                writer.error(exc)
            writer.publish_counters()
    finally:
        writer.publish_counters()
        sock.close()
        shared.release()
        shm.close()
