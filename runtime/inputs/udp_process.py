"""A live frame source whose receiving and decoding run in a child process.

Why: in :class:`~facepuppet.runtime.inputs.udp.UdpSource` the receive thread
decodes datagrams in pure Python and needs the GIL, which the frame loop holds
through every moderngl call (a draw and ``finish()`` on llvmpipe: 10-30 ms).
Datagrams then wait in the kernel until the loop lets go (measured in a live
run on 2 cores: p50 3 ms, p99 16 ms when the machine was quiet, hundreds of ms
under load), and each hand-over of the GIL costs the loop a switch. Here a
child process (its own interpreter, its own GIL) reads and decodes, and
sends each decoded frame through a socket pair; the frame loop reads what
arrived once per tick, keeps the newest frame and nothing else in its
process competes for its GIL.

Same interface as :class:`UdpSource`: ``start()``/``stop()``, ``address``,
``latest(t) -> (frame or None, stale)``, ``frames_taken``, ``watched``, ``counters``,
``last_error``, ``on_packet``. Differences:

* the receive time is always the kernel's arrival stamp on the monotonic clock
  (``SO_TIMESTAMPNS``; the child's read time where there is none): no ``clock``;
* ``on_packet`` (the recorder) runs in the *parent*: the child sends each
  accepted datagram through the channel, where it waits (up to ``ring_bytes``,
  4 MiB, on each side) until
  :meth:`UdpProcessSource.deliver_packets` hands it to ``on_packet`` when the
  frame loop's recording hook calls it (once a tick), :meth:`stop` the rest;
  beyond that it is dropped and counted (``packets_ring_dropped``), the child
  never blocks. :meth:`latest` has no callbacks;
* the adapter is copied into the child (pickled), so ``source.adapter.counters``
  stays at zero: read :attr:`counters`, which the child keeps current;
* :meth:`UdpProcessSource.wait_for_frame` sleeps on the channel, which becomes
  readable when the child sends (the frame loop's draw on arrival);
* frames with more than ``MAX_WEIGHTS`` weights or ``MAX_MARKERS`` markers are
  dropped and counted (``frame_too_large``).

Why the frame is never torn, on any CPU: nothing is shared between the
processes. Each frame, with the names it uses, crosses as one message of the
channel (:mod:`~facepuppet.runtime.inputs.udp_channel`), a Unix stream socket:
the kernel copies the bytes under the socket's lock and delivers them in the
order they were sent, so the parent acts on a message only once it holds all of
it, and on the names, counters and datagrams sent before it first. Frames the
parent did not read in time are dropped when a newer one comes (in the child
when the channel is full, here otherwise) and counted stale from the frame
numbers the child gives them. The child's side is
:mod:`~facepuppet.runtime.inputs.udp_child`.
"""

from __future__ import annotations

import collections
import os
import pickle
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.udp import bind_udp, bound_address, enable_drop_count, normalise_allow
from facepuppet.runtime.inputs.udp_channel import (
    COMPLETED,
    COUNTER_NAME,
    COUNTERS,
    ERROR,
    FRAME,
    INDEX,
    MAX_NAMES,
    PACKET,
    PACKET_HEAD,
    READY,
    RING_BYTES,
    WATCHED,
    ChannelError,
    Inbox,
    frame_from,
    packet_cost,
    read_frame,
)

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import InputAdapter

START_TIMEOUT_S = 30.0  # a spawned interpreter importing NumPy on a loaded 2-core machine
STOP_TIMEOUT_S = 5.0  # the child flushes for at most 4 s (udp_child.STOP_FLUSH_S), then is killed


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
    ring_bytes : int, how many bytes of datagrams may wait for ``on_packet`` on each side of the channel
        (a multiple of 16, >= 128 KiB; a datagram counts its size plus 16, rounded up to 16)
    watch : str or None, an OSC address: the child counts the decoded OSC messages with exactly this
        address (bundles included) in accepted datagrams in :attr:`watched`, without shipping every
        datagram to this process as ``on_packet`` does

    :meth:`latest`, :meth:`pending`, :meth:`deliver_packets`, :attr:`counters` and :attr:`watched` may be
    called from any thread (the panel reads counters while the loop takes frames): each reads the channel
    under one lock.
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
        self.drops_reported = False  # whether the kernel hands the child its drop count (set at start)
        self._lock = threading.RLock()
        self._sock: socket.socket | None = None
        self._process = None
        self._chan: socket.socket | None = None        # this process's end of the channel
        self._chan_child: socket.socket | None = None  # the child's end, held here too: never end of file here
        self._inbox: Inbox | None = None
        self._own = {"snapshot_busy": 0, "internal_error": 0, "packets_ring_dropped": 0}
        self._reset()

    def _reset(self) -> None:
        """What a (re)start begins afresh: the new child's counters, names and frame numbers."""
        self._stale_dropped = 0
        self._taken = 0
        self._ready = False
        self._newest: tuple | None = None  # the newest frame received and not taken, not yet a Frame
        self._names: list[object] = [None] * MAX_NAMES  # the child's name slots
        self._counter_names: dict[int, str] = {}
        self._counter_values: tuple[int, ...] = ()
        self._watched = 0
        self._packets: collections.deque[tuple[bytes, float, tuple, int]] = collections.deque()
        self._packet_bytes = 0

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
        self.drops_reported = enable_drop_count(sock)  # a flag of the socket, which the child reads
        self._sock = sock
        self._chan, self._chan_child = socket.socketpair()
        self._chan.setblocking(False)
        self._inbox = Inbox(self._chan)
        self._reset()
        # PR_SET_PDEATHSIG follows the starting *thread*: asked for only from the main thread
        deathsig = threading.current_thread() is threading.main_thread()
        # A fresh interpreter (not fork: this process may hold a GL context and threads; not
        # multiprocessing's spawn: it re-imports the caller's __main__), given the sockets by descriptor.
        self._process = subprocess.Popen(
            [sys.executable, "-c", "from facepuppet.runtime.inputs.udp_child import child_main; child_main()"],
            stdin=subprocess.PIPE, pass_fds=(sock.fileno(), self._chan_child.fileno()))
        try:
            self._process.stdin.write(pickle.dumps((sock.fileno(), sock.family, self._chan_child.fileno(),
                                                    self.adapter, self.allow, self.on_packet is not None,
                                                    os.getpid(), self.watch, self.ring_bytes, deathsig)))
            self._process.stdin.close()
        except (OSError, pickle.PicklingError) as exc:
            self.stop()
            raise RuntimeError(f"UdpProcessSource: cannot hand the adapter to the receiving process: {exc}") from exc
        end = time.monotonic() + START_TIMEOUT_S
        while True:
            select.select([self._chan], [], [], 0.01)
            with self._lock:
                self._drain()
            if self._ready:
                return self
            if self._process.poll() is not None or time.monotonic() > end:
                code = self._process.poll()
                self.stop()
                raise RuntimeError(f"UdpProcessSource: the receiving process did not start (exit code {code})")

    def stop(self) -> None:
        """Stop the child (at once; it sends what it queued first), hand on the last datagrams, free everything.

        The counters, ``watched`` and ``last_error`` keep their final values.
        """
        process = self._process
        if process is not None:
            try:
                self._chan.send(b"\0")  # the child's request to stop (its end of file would mean: parent gone)
            except OSError:
                pass
            deadline = time.monotonic() + STOP_TIMEOUT_S
            while process.poll() is None:  # read while it flushes: a full channel would keep it waiting
                if time.monotonic() > deadline:
                    process.kill()
                    process.wait(timeout=5.0)
                    break
                select.select([self._chan], [], [], 0.02)
                self._drain_and_deliver()
            self._process = None
        if self._inbox is not None:
            self._drain_and_deliver()  # what the child sent before it left
            with self._lock:
                self._inbox = None
                self._newest = None
            for chan in (self._chan, self._chan_child):
                chan.close()
            self._chan = self._chan_child = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> UdpProcessSource:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _drain_and_deliver(self) -> None:
        with self._lock:
            self._drain()
        self.deliver_packets()

    def _drain(self) -> None:
        """Act on every whole message the channel holds (caller holds the lock); errors are counted."""
        if self._inbox is None:
            return
        try:
            messages = self._inbox.read()
        except ChannelError as exc:
            self._own["internal_error"] += 1
            self.last_error = exc
            return
        for kind, body in messages:
            try:
                if kind == FRAME:
                    self._on_frame(body)
                elif kind == PACKET:
                    self._on_packet(body)
                elif kind == COUNTERS:
                    values = struct.unpack_from(f"<{len(body) // 8}q", body)
                    self._watched = max(self._watched, values[0])
                    self._counter_values = values[1:]
                elif kind == COUNTER_NAME:
                    self._counter_names[INDEX.unpack_from(body)[0]] = body[INDEX.size:].decode("utf-8", "replace")
                elif kind == ERROR:
                    self.last_error = RuntimeError(body.decode("utf-8", "replace"))
                elif kind == READY:
                    self._ready = True
                else:
                    raise ChannelError(f"receiver channel: unknown message kind {kind}")
            except Exception as exc:  # a message this side cannot read: count, never raise
                self._own["internal_error"] += 1
                self.last_error = exc

    def _on_frame(self, body: bytes) -> None:
        """Keep a frame as the newest (the one before, if not taken, is stale), its names looked up now: a
        later frame may give their slots to other names."""
        head, names, off = read_frame(body, self._names)
        self._watched = max(self._watched, head[WATCHED])
        self._newest = (head, names, body, off)

    def _on_packet(self, body: bytes) -> None:
        if self.on_packet is None:
            return
        t, port, host_len = PACKET_HEAD.unpack_from(body)
        start = PACKET_HEAD.size
        data = body[start + host_len:]
        cost = packet_cost(host_len, len(data))
        if self._packet_bytes + cost > self.ring_bytes:
            self._own["packets_ring_dropped"] += 1
            return
        self._packets.append((data, t, (body[start:start + host_len].decode("ascii"), port), cost))
        self._packet_bytes += cost

    @property
    def watched(self) -> int:
        """OSC messages to ``watch`` accepted so far (a count that only grows)."""
        with self._lock:
            self._drain()
            return self._watched

    @property
    def frames_taken(self) -> int:
        """Frames completed up to the newest one :meth:`latest` handed out (0 before any)."""
        return self._taken

    def pending(self) -> bool:
        """A frame not yet taken is there (:meth:`latest` would hand it out)."""
        with self._lock:
            self._drain()
            return self._newest is not None

    @property
    def wake_fd(self) -> int | None:
        """This process's end of the channel (None before start): readable when the child has sent something.
        Never read it directly (:meth:`pending` does): :class:`~facepuppet.runtime.inputs.arrival.ArrivalWaiter`
        selects on it and asks :meth:`pending`."""
        return None if self._chan is None else self._chan.fileno()

    def wait_for_frame(self, timeout_s: float) -> bool:
        """Sleep until a frame not yet taken is there (True) or ``timeout_s`` passes (False)."""
        chan = self._chan
        if chan is None:
            time.sleep(max(0.0, timeout_s))
            return False
        deadline = time.monotonic() + timeout_s
        while not self.pending():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            select.select([chan], [], [], left)
        return True

    def latest(self, t: float | None = None) -> tuple[Frame | None, int]:
        """(newest frame not yet taken or None, frames overwritten unseen since the last call).

        No callbacks (:meth:`deliver_packets` hands datagrams on). ``t`` is accepted for the
        source interface and ignored.
        """
        with self._lock:
            self._drain()
            newest, self._newest = self._newest, None
            if newest is None:
                return None, 0
            try:
                frame = frame_from(*newest)
            except Exception as exc:  # a message this side cannot read: count, never raise
                self._own["internal_error"] += 1
                self.last_error = exc
                return None, 0
            completed = newest[0][COMPLETED]
            stale = completed - self._taken - 1
            self._taken = completed
            self._stale_dropped += stale
            return frame, stale

    def deliver_packets(self) -> None:
        """Hand every datagram received to ``on_packet``, in order (its errors are counted, never raised).

        The child sends a datagram before the frame decoded from it, so after :meth:`latest` every datagram
        behind the frame taken is here: called after the snapshot (the recording hook does), they reach the
        recorder before that tick's TICK record.
        """
        on_packet = self.on_packet
        if on_packet is None:
            return
        with self._lock:
            self._drain()
            while self._packets:
                data, t, sender, cost = self._packets.popleft()
                self._packet_bytes -= cost
                try:
                    on_packet(data, t, sender)
                except Exception as exc:
                    self._own["internal_error"] += 1
                    self.last_error = exc

    @property
    def counters(self) -> dict[str, int]:
        """The child's counters (adapter's merged with packets, filtered_sender, internal_error,
        waited_over_1ms, kernel_dropped (None: the kernel does not say), frame_too_large, packets_ring_dropped,
        names_full (the counter names and errors
        passed META_BYTES), names_too_large (one name record over MAX_NAME_RECORD)) plus snapshot_busy (0: a
        frame arrives whole, no read is retried), stale_dropped and rcvbuf_bytes; ``internal_error`` and
        ``packets_ring_dropped`` add both processes'."""
        with self._lock:
            self._drain()
            values = self._counter_values
            merged = {name: values[i] if i < len(values) else 0 for i, name in self._counter_names.items()}
            for name, value in self._own.items():
                merged[name] = merged.get(name, 0) + value
        merged["kernel_dropped"] = merged.get("kernel_dropped", 0) if self.drops_reported else None
        merged["stale_dropped"] = self._stale_dropped
        merged["rcvbuf_bytes"] = self.rcvbuf_bytes
        return merged
