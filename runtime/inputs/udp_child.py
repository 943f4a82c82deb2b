"""The receiving process of :class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`.

Started as ``python -c "from facepuppet.runtime.inputs.udp_child import child_main; child_main()"``
with its arguments pickled on stdin and the bound socket passed by descriptor.
It reads each datagram with its kernel arrival stamp, drops senders outside
``allow``, counts the OSC messages to the watched address, copies accepted
datagrams into the ring when the parent has an ``on_packet``, decodes with the
adapter and publishes the frame (seqlock) and the counters into the shared
block laid out by :class:`~facepuppet.runtime.inputs.udp_shared.SharedBlock`. It never
raises, never blocks on the parent, and leaves when the parent is gone.
"""

from __future__ import annotations

import json
import os
import pickle
import select
import socket
import sys
import time
from multiprocessing import shared_memory

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.udp import (
    POLL_TIMEOUT_S,
    control_only,
    count_messages,
    enable_kernel_stamps,
    receive,
    sender_allowed,
    watch_needle,
)
from facepuppet.runtime.inputs.udp_shared import (
    CHANNELS,
    COMPLETED,
    FLAGS,
    HAS_MARKERS,
    HAS_ROTATION,
    HAS_TRANSLATION,
    HAS_WEIGHTS,
    MARKER_NAMES,
    MAX_COUNTERS,
    MAX_ERRORS_LOGGED,
    MAX_MARKERS,
    MAX_NAME_RECORD,
    MAX_WEIGHTS,
    META_BYTES,
    META_END,
    N_MARKERS,
    N_WEIGHTS,
    NAME,
    NAMES_BYTES,
    NAMES_END,
    NUMBER,
    READY,
    RECORD,
    RELOG_AFTER,
    RING_R,
    RING_W,
    SEQ,
    SOURCE,
    STOP,
    WATCHED,
    WRAP,
    SharedBlock,
    padded,
)

PR_SET_PDEATHSIG = 1  # linux/prctl.h
MAX_IDS = 256  # names the child remembers the ring position of


class _Writer:
    """The child's side: names ring, counter-name and error log, counters, slot, datagram ring."""

    def __init__(self, shared: SharedBlock, adapter):
        self.shared, self.adapter = shared, adapter
        self.ids: dict[tuple[str, object], int] = {}
        self.counter_index: dict[str, int] = {}
        self.errors_logged = 0
        self.own = {"packets": 0, "filtered_sender": 0, "internal_error": 0, "waited_over_1ms": 0,
                    "frame_too_large": 0, "packets_ring_dropped": 0, "names_full": 0, "names_too_large": 0}

    def log(self, kind: str, key, value) -> bool:
        """Append one record to the counter-name and error log; False (counted) when it is full."""
        payload = json.dumps([kind, key, value]).encode()
        ctl, pos = self.shared.ctl, self.shared.ctl[META_END]
        if pos + 4 + len(payload) > META_BYTES:
            self.own["names_full"] += 1
            return False
        NAME.pack_into(self.shared.meta, pos, len(payload))
        self.shared.meta[pos + 4:pos + 4 + len(payload)] = payload
        ctl[META_END] = pos + 4 + len(payload)  # published after the bytes
        return True

    def error(self, exc: BaseException) -> None:
        """Log an error for ``last_error`` (the first MAX_ERRORS_LOGGED only: the log is bounded)."""
        if self.errors_logged < MAX_ERRORS_LOGGED:
            self.errors_logged += 1
            self.log("error", 0, repr(exc)[:500])

    def name_id(self, kind: str, value) -> int | None:
        """The id of ``value`` (its record's absolute position in the names ring), written when new or old."""
        if value is None:
            return -1
        key = (kind, value)
        ctl = self.shared.ctl
        i = self.ids.get(key)
        if i is not None and ctl[NAMES_END] - i <= RELOG_AFTER:
            return i
        payload = json.dumps([kind, list(value) if isinstance(value, tuple) else value],
                             ensure_ascii=False).encode()
        n = NAME.size + len(payload)
        if n > MAX_NAME_RECORD:
            self.own["names_too_large"] += 1
            return None
        pos = ctl[NAMES_END]
        p = pos % NAMES_BYTES
        if p + n > NAMES_BYTES:  # a record is contiguous: go on at the ring's start
            pos += NAMES_BYTES - p
            p = 0
        names = self.shared.names
        NAME.pack_into(names, p, len(payload))
        names[p + NAME.size:p + n] = payload
        ctl[NAMES_END] = pos + n  # published after the bytes
        if len(self.ids) >= MAX_IDS:  # forget what the ring has overwritten (or everything)
            end = pos + n
            self.ids = {k: v for k, v in self.ids.items() if end - v <= RELOG_AFTER}
            if len(self.ids) >= MAX_IDS:
                self.ids = {}
        self.ids[key] = pos
        return pos

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
        n = padded(RECORD.size + len(host) + len(data))
        w = ctl[RING_W]
        free = size - (w - ctl[RING_R])
        p = w % size
        gap = size - p if p + n > size else 0  # the record must be contiguous: wrap to the start
        if gap + n > free:
            self.own["packets_ring_dropped"] += 1
            return
        if gap:
            RECORD.pack_into(ring, p, WRAP, 0.0, 0, 0)
            w, p = w + gap, 0
        RECORD.pack_into(ring, p, len(data), t, int(sender[1]) & 0xFFFF, len(host))
        start = p + RECORD.size
        ring[start:start + len(host)] = host
        ring[start + len(host):start + len(host) + len(data)] = data
        ctl[RING_W] = w + n  # published after the bytes


def child_main() -> None:
    """Entry point of the receiving process: its arguments come pickled on stdin."""
    (shm_name, ring_bytes, fd, family, adapter, allow, want_packets, parent_pid, watch, wake_fd, alive_fd,
     deathsig) = pickle.load(sys.stdin.buffer)
    if deathsig:
        die_with_parent()
    if os.getppid() != parent_pid:  # the parent died before we got here
        return
    _child(shm_name, ring_bytes, socket.socket(family, socket.SOCK_DGRAM, fileno=fd), adapter, allow, want_packets,
           parent_pid, watch, wake_fd, alive_fd)


def die_with_parent() -> bool:
    """Ask the kernel to kill this process when its parent dies (Linux ``PR_SET_PDEATHSIG``); False elsewhere.

    The "parent" is the thread that started us, so the parent sets ``deathsig`` only when it starts the child
    from its main thread; the ``alive_fd`` pipe covers every other case.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _child(shm_name: str, ring_bytes: int, sock: socket.socket, adapter, allow, want_packets: bool,
           parent_pid: int, watch: str | None = None, wake_fd: int | None = None,
           alive_fd: int | None = None) -> None:
    """The receiving process: read, stamp, filter, copy for on_packet, decode, publish, wake; never raises.

    ``wake_fd``, the non-blocking write end of the parent's pipe, gets a byte
    after each published frame (a full pipe means the parent is awake anyway).
    ``alive_fd`` is the read end of a pipe whose write end only the parent
    holds: it becomes readable (end of file) the moment the parent is gone,
    however it ended, and the child polls it with the socket before every read,
    so a flooded socket cannot keep the child (and the port) alive.
    """
    shm = shared_memory.SharedMemory(name=shm_name)
    try:  # the parent owns (and unlinks) the block: this process must not have it tracked as its own
        from multiprocessing import resource_tracker

        resource_tracker.unregister(shm._name, "shared_memory")
    except Exception:
        pass
    shared = SharedBlock(shm, ring_bytes)
    writer = _Writer(shared, adapter)
    own, ctl, handle = writer.own, shared.ctl, adapter.handle
    stamped = enable_kernel_stamps(sock)
    needle = watch_needle(watch)
    sock.settimeout(POLL_TIMEOUT_S)
    writer.publish_counters()
    ctl[READY] = 1
    poller = select.poll()
    poller.register(sock.fileno(), select.POLLIN)
    if alive_fd is not None:
        poller.register(alive_fd, select.POLLIN)
    poll_ms = int(POLL_TIMEOUT_S * 1000)
    try:
        while not ctl[STOP]:
            events = poller.poll(poll_ms)
            if alive_fd is not None and any(fd == alive_fd for fd, _ in events):
                break  # the parent is gone (its end of the pipe closed)
            if not events:
                if os.getppid() != parent_pid:  # no pipe (or not yet noticed): the parent is gone
                    break
                continue
            try:
                data, sender, t = receive(sock, stamped, time.monotonic, own)
            except (TimeoutError, BlockingIOError, InterruptedError):
                continue
            except OSError as exc:
                own["internal_error"] += 1
                writer.error(exc)
                time.sleep(POLL_TIMEOUT_S)
                continue
            try:
                own["packets"] += 1
                if allow is not None and not sender_allowed(sender[0], allow):
                    own["filtered_sender"] += 1
                else:
                    watched = 0 if watch is None else count_messages(data, watch, needle)
                    ctl[WATCHED] += watched
                    if want_packets:
                        writer.put_packet(data, t, sender)
                    frame = None if control_only(data, watched) else handle(data, t)
                    if frame is not None:
                        writer.publish(frame)
                        if wake_fd is not None:
                            try:
                                os.write(wake_fd, b"\1")
                            except BlockingIOError:
                                pass
            except Exception as exc:  # nothing escapes
                own["internal_error"] += 1
                writer.error(exc)
            writer.publish_counters()
    finally:
        writer.publish_counters()
        sock.close()
        shared.release()
        shm.close()
