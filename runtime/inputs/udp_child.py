"""The receiving process of :class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`.

Started as ``python -c "from facepuppet.runtime.inputs.udp_child import child_main; child_main()"``
with its arguments pickled on stdin, and given the bound UDP socket and its end of the channel
(:mod:`~facepuppet.runtime.inputs.udp_channel`) by descriptor. It reads each datagram with its kernel
arrival stamp, drops senders outside ``allow``, counts the OSC messages to the watched address, queues
accepted datagrams for the parent's ``on_packet`` when it has one, decodes with the adapter and sends the
frame, the names it uses and the counters through the channel. It never raises, never blocks on the
parent, and leaves when the parent asks (flushing what it queued) or is gone (at once).
"""

from __future__ import annotations

import collections
import json
import math
import os
import pickle
import select
import socket
import struct
import sys
import time

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.udp import (
    POLL_TIMEOUT_S,
    ArrivalOrder,
    control_only,
    count_messages,
    enable_kernel_stamps,
    receive,
    sender_allowed,
    watch_needle,
)
from facepuppet.runtime.inputs.udp_channel import (
    COUNTER_NAME,
    COUNTERS,
    ERROR,
    FRAME,
    FRAME_FIELDS,
    FRAME_NAMES,
    HAS_MARKERS,
    HAS_ROTATION,
    HAS_TRANSLATION,
    HAS_WEIGHTS,
    INDEX,
    MAX_COUNTERS,
    MAX_ERRORS_LOGGED,
    MAX_MARKERS,
    MAX_NAME_RECORD,
    MAX_NAMES,
    MAX_WEIGHTS,
    META_BYTES,
    NAME_FIELDS,
    PACKET,
    PACKET_HEAD,
    READY,
    RING_BYTES,
    Outbox,
    message,
    packet_cost,
)

PR_SET_PDEATHSIG = 1  # linux/prctl.h
STOP_FLUSH_S = 4.0  # asked to stop, the child sends what it queued for at most this long


def name_record(kind: str, value: object) -> bytes:
    """A name's definition as the parent reads it: JSON ``[kind, value]`` (a tuple as a list)."""
    return json.dumps([kind, list(value) if isinstance(value, tuple) else value], ensure_ascii=False).encode()


class _Publisher:
    """The child's side of the protocol: frames, datagrams for the recorder, counters and errors, queued in
    an :class:`~facepuppet.runtime.inputs.udp_channel.Outbox` in the order the parent must read them."""

    def __init__(self, chan: socket.socket, adapter, packet_bytes: int) -> None:
        self.adapter = adapter
        self.outbox = Outbox(chan, packet_bytes, self._encode_frame, self._encode_counters)
        # names the parent holds -> their slot, least recently used first
        self.names: collections.OrderedDict[tuple[str, object], int] = collections.OrderedDict()
        self.completed = 0  # frames published
        self.watched = 0
        self.counter_index: dict[str, int] = {}
        self.meta_bytes = 0
        self.errors_logged = 0
        self.order = ArrivalOrder()  # receive times that never go back (see ArrivalOrder)
        self.own = {"packets": 0, "filtered_sender": 0, "internal_error": 0, "waited_over_1ms": 0,
                    "kernel_dropped": 0, "frame_too_large": 0, "packets_ring_dropped": 0, "names_full": 0,
                    "names_too_large": 0}

    def ready(self) -> None:
        self.outbox.put(message(READY))
        self.publish_counters()

    def log(self, data: bytes) -> bool:
        """Queue a counter name or an error; False (counted names_full) once META_BYTES are spent."""
        if self.meta_bytes + len(data) > META_BYTES:
            self.own["names_full"] += 1
            return False
        self.meta_bytes += len(data)
        return self.outbox.put(data)

    def error(self, exc: BaseException) -> None:
        """Report an error for ``last_error`` (the first MAX_ERRORS_LOGGED only: the log is bounded)."""
        if self.errors_logged < MAX_ERRORS_LOGGED:
            self.errors_logged += 1
            self.log(message(ERROR, repr(exc)[:500].encode("utf-8", "replace")))

    def _merged(self) -> dict[str, int]:
        merged = dict(self.adapter.counters)
        for name, value in self.own.items():
            merged[name] = merged.get(name, 0) + value
        return merged

    def publish_counters(self) -> None:
        """Name new counters (before the values that use them) and have the values sent after what is queued."""
        index = self.counter_index
        for name in self._merged():
            if name not in index:
                if len(index) >= MAX_COUNTERS or not self.log(
                        message(COUNTER_NAME, INDEX.pack(len(index)) + str(name).encode("utf-8", "replace"))):
                    continue
                index[name] = len(index)
        self.outbox.put_counters()

    def _encode_counters(self) -> bytes:
        merged, values = self._merged(), [0] * len(self.counter_index)
        for name, i in self.counter_index.items():
            values[i] = int(merged.get(name, 0))
        return message(COUNTERS, struct.pack(f"<{1 + len(values)}q", self.watched, *values))

    def publish(self, frame: Frame) -> None:
        """Queue ``frame``, its arrays copied now (an adapter may reuse them); refused and counted when over
        the bounds."""
        n_weights = 0 if frame.weights is None else len(frame.weights)
        n_markers = 0 if frame.markers is None else len(frame.markers)
        if n_weights > MAX_WEIGHTS or n_markers > MAX_MARKERS:
            self.own["frame_too_large"] += 1
            return
        names = []
        for kind, value in zip(NAME_FIELDS, (frame.channels, frame.marker_names, frame.source)):
            if value is None:
                names.append(None)
                continue
            key = (kind, value)
            record = None if key in self.names else name_record(kind, value)
            if record is not None and INDEX.size + len(record) > MAX_NAME_RECORD:
                self.own["names_too_large"] += 1
                return
            names.append((key, record))
        flags = ((HAS_WEIGHTS if frame.weights is not None else 0) | (HAS_MARKERS if frame.markers is not None else 0)
                 | (HAS_ROTATION if frame.head_rotation is not None else 0)
                 | (HAS_TRANSLATION if frame.head_translation is not None else 0))
        rotation = [0.0] * 4 if frame.head_rotation is None else \
            np.asarray(frame.head_rotation, np.float32).reshape(4).tolist()
        translation = [0.0] * 3 if frame.head_translation is None else \
            np.asarray(frame.head_translation, np.float32).reshape(3).tolist()
        arrays = b""
        if n_weights:
            arrays += np.asarray(frame.weights, "<f4").tobytes()
        if n_markers:
            arrays += np.asarray(frame.markers, "<f4").reshape(-1).tobytes()
        fields = FRAME_FIELDS.pack(self.completed + 1, int(frame.number), self.watched, flags, n_weights,
                                   n_markers, frame.t, frame.t_sender, frame.audio_level, *rotation, *translation)
        self.completed += 1
        self.outbox.put_frame((fields, names, arrays))

    def _encode_frame(self, item) -> bytes:
        """The FRAME message, when its turn to be sent comes: a name the parent does not hold yet is defined
        in it, in the slot of the least recently used one (never one this frame uses)."""
        fields, names, arrays = item
        slots, lengths, records = [-1, -1, -1], [0, 0, 0], []
        for i, entry in enumerate(names):
            if entry is not None and entry[0] in self.names:
                self.names.move_to_end(entry[0])
                slots[i] = self.names[entry[0]]
        for i, entry in enumerate(names):
            if entry is None or slots[i] != -1:
                continue
            key, record = entry
            if record is None:
                record = name_record(*key)
            slot = len(self.names) if len(self.names) < MAX_NAMES else self.names.popitem(last=False)[1]
            self.names[key] = slot
            slots[i], lengths[i] = slot, len(record)
            records.append(record)
        return message(FRAME, b"".join((fields, FRAME_NAMES.pack(*slots, *lengths), *records, arrays)))

    def flush(self) -> None:
        """Send what the channel takes now; an error of this side is counted (the messages it took are lost,
        the stream stays whole). Raises OSError when the parent is gone."""
        try:
            self.outbox.flush()
        except OSError:
            raise
        except Exception as exc:
            self.own["internal_error"] += 1
            self.error(exc)

    def put_packet(self, data: bytes, t: float, sender) -> None:
        """Queue one datagram for the parent's ``on_packet``; drop and count when the queue is full."""
        host = str(sender[0]).encode("ascii", "replace")[:255]
        body = PACKET_HEAD.pack(t, int(sender[1]) & 0xFFFF, len(host)) + host + data
        if not self.outbox.put(message(PACKET, body), packet_cost(len(host), len(data))):
            self.own["packets_ring_dropped"] += 1


def child_main() -> None:
    """Entry point of the receiving process: its arguments come pickled on stdin."""
    (fd, family, chan_fd, adapter, allow, want_packets, parent_pid, watch, packet_bytes,
     deathsig) = pickle.load(sys.stdin.buffer)
    if deathsig:
        die_with_parent()
    if os.getppid() != parent_pid:  # the parent died before we got here
        return
    _child(socket.socket(family, socket.SOCK_DGRAM, fileno=fd), socket.socket(fileno=chan_fd), adapter, allow,
           want_packets, parent_pid, watch, packet_bytes)


def die_with_parent() -> bool:
    """Ask the kernel to kill this process when its parent dies (Linux ``PR_SET_PDEATHSIG``); False elsewhere.

    The "parent" is the thread that started us, so the parent sets ``deathsig`` only when it starts the child
    from its main thread; the channel's end of file covers every other case.
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


def _parent_wants(chan: socket.socket) -> str:
    """What the readable channel says: "stop" (the parent sent a byte), "gone" (end of file: every copy of
    the parent's end is closed, however the parent ended) or "" (nothing after all)."""
    try:
        return "stop" if chan.recv(64) else "gone"
    except (BlockingIOError, InterruptedError):
        return ""
    except OSError:
        return "gone"


def _flush_before_leaving(publisher: _Publisher, chan: socket.socket) -> None:
    """Send what is queued, waiting on the socket (the parent reads while it waits for this process to exit),
    for at most STOP_FLUSH_S."""
    deadline = time.monotonic() + STOP_FLUSH_S
    poller = select.poll()
    poller.register(chan.fileno(), select.POLLOUT)
    while True:
        publisher.flush()
        left = deadline - time.monotonic()
        if publisher.outbox.empty or left <= 0:
            return
        poller.poll(int(math.ceil(left * 1000)))


def _child(sock: socket.socket, chan: socket.socket, adapter, allow, want_packets: bool, parent_pid: int,
           watch: str | None = None, packet_bytes: int = RING_BYTES) -> None:
    """The receiving process: read, stamp, filter, queue for on_packet, decode, send; never raises.

    One ``poll`` waits on the UDP socket and the channel: readable, the channel says stop or parent gone
    (:func:`_parent_wants`); writable again, it takes the rest of a send the socket took in part. A frame
    is sent as soon as it is decoded; what comes without a frame waits up to FLUSH_DELAY_S
    (:class:`~facepuppet.runtime.inputs.udp_channel.Outbox`). Where the channel's end of file is missed
    (no event while the parent dies), the parent's pid is checked whenever the poll times out.
    """
    chan.setblocking(False)
    publisher = _Publisher(chan, adapter, packet_bytes)
    outbox, handle = publisher.outbox, adapter.handle
    stamped = enable_kernel_stamps(sock)
    needle = watch_needle(watch)
    sock.settimeout(POLL_TIMEOUT_S)
    sock_fd, chan_fd = sock.fileno(), chan.fileno()
    poller = select.poll()
    poller.register(sock_fd, select.POLLIN)
    chan_events = select.POLLIN
    poller.register(chan_fd, chan_events)
    try:
        publisher.ready()
        publisher.flush()
        while True:
            wait_s = POLL_TIMEOUT_S
            if not outbox.blocked and outbox.due_at != math.inf:
                wait_s = min(wait_s, max(0.0, outbox.due_at - time.monotonic()))
            events = poller.poll(int(math.ceil(wait_s * 1000)))
            readable = False
            for fd, mask in events:
                if fd == sock_fd:
                    readable = True
                elif mask & (select.POLLIN | select.POLLHUP | select.POLLERR):
                    wants = _parent_wants(chan)
                    if wants == "stop":
                        publisher.publish_counters()
                        _flush_before_leaving(publisher, chan)
                        return
                    if wants == "gone":
                        return
            if not events and os.getppid() != parent_pid:  # the parent is gone (its end of file not seen)
                return
            if readable:
                _take_one(sock, stamped, publisher, allow, watch, needle, want_packets, handle)
            if outbox.blocked or outbox.due_at <= time.monotonic():
                publisher.flush()
            wanted = select.POLLIN | (select.POLLOUT if outbox.blocked else 0)
            if wanted != chan_events:
                poller.modify(chan_fd, wanted)
                chan_events = wanted
    except OSError:  # the channel broke: the parent is gone
        pass
    finally:
        sock.close()
        chan.close()


def _take_one(sock: socket.socket, stamped: bool, publisher: _Publisher, allow, watch: str | None,
              needle: bytes | None, want_packets: bool, handle) -> None:
    """Read, filter, count, queue and decode one datagram; never raises."""
    own = publisher.own
    try:
        data, sender, t = receive(sock, stamped, time.monotonic, own, publisher.order)
    except (TimeoutError, BlockingIOError, InterruptedError):
        return
    except OSError as exc:
        own["internal_error"] += 1
        publisher.error(exc)
        time.sleep(POLL_TIMEOUT_S)
        return
    try:
        own["packets"] += 1
        if allow is not None and not sender_allowed(sender[0], allow):
            own["filtered_sender"] += 1
        else:
            watched = 0 if watch is None else count_messages(data, watch, needle)
            publisher.watched += watched
            if want_packets:
                publisher.put_packet(data, t, sender)
            frame = None if control_only(data, watched) else handle(data, t)
            if frame is not None:
                publisher.publish(frame)
    except Exception as exc:  # nothing escapes
        own["internal_error"] += 1
        publisher.error(exc)
    publisher.publish_counters()
