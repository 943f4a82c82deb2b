"""A live frame source: one UDP socket, one receive thread, one adapter, one slot.

The receive thread (a daemon) reads datagrams with a plain socket, stamps each
with ``clock()`` at once, drops senders outside ``allow`` (counted), hands the
bytes to ``on_packet`` (a recorder; must not block) and to the adapter, and
puts a completed frame in a slot: one tuple assignment ``(sequence, frame)``,
atomic under the GIL, so the frame loop never waits on a lock and nothing is
queued. :meth:`UdpSource.latest` answers like
:meth:`~facepuppet.runtime.recording.replay_source.ReplaySource.latest`: the newest frame not
yet taken and how many completed frames were overwritten since the last call.

The thread never raises: anything escaping the adapter or ``on_packet`` is
counted as ``internal_error`` (the last one is kept in :attr:`UdpSource.last_error`)
and the thread goes on.

Receive time: with the default clock (``time.monotonic``) each datagram is
stamped with the kernel's own arrival time (``SO_TIMESTAMPNS``, converted from
the real-time clock to the monotonic one), not with the moment the thread got
round to reading it: a receiver starved of the GIL by the frame loop reads
datagrams several milliseconds after they arrived (measured p50 3 ms, p99 16 ms
in a live run on llvmpipe, far more under load), and a late stamp would hide
that wait from the latency stats. ``counters["waited_over_1ms"]`` counts the
datagrams read more than 1 ms after they arrived. With another clock (tests),
or where the kernel gives no stamp, ``clock()`` at read time is used.

For a receiver whose decoding never competes with the frame loop for the GIL,
see :class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource` (same interface,
decoding in a child process).

Kernel drops: a datagram that finds the socket's receive buffer full is dropped by the kernel, before any
counter of ours sees it (up to 30 % at 3,000 datagrams/s on a loaded machine). Linux counts them per socket
and, with ``SO_RXQ_OVFL`` set, hands the running count (a uint32) with each datagram queued after a drop;
``counters["kernel_dropped"]`` keeps it (exact: the kernel's own count, seen with the next datagram read).
Where the option is missing it is None, "unknown", never a 0 that would read as "none dropped".

The socket asks for a large kernel receive buffer (``SOCKET_BUFFER``, 4 MiB;
Linux grants at most ``net.core.rmem_max``, doubled for its bookkeeping, and
the grant is in ``counters["rcvbuf_bytes"]``): the thread drains the socket only
when it holds the GIL, and whatever arrives meanwhile must wait in the kernel.

Which address to bind is the caller's choice (the ``run`` command defaults to
127.0.0.1 and binds elsewhere only when asked); port 0 picks a free port.
"""

from __future__ import annotations

import errno
import functools
import ipaddress
import math
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs import osc

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import InputAdapter

RECV_BUFFER = 65536
POLL_TIMEOUT_S = 0.05  # how often the thread looks at the stop flag while idle
SOCKET_BUFFER = 4 << 20  # kernel receive buffer asked for: holds what arrives while a draw runs
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; Python's socket module does not name it
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux: the kernel's drop count with each datagram
_ANCILLARY = socket.CMSG_SPACE(16) + socket.CMSG_SPACE(4) if hasattr(socket, "CMSG_SPACE") else 0
_TIMESPEC = struct.Struct("qq")
_DROPS = struct.Struct("=I")  # SO_RXQ_OVFL's payload: a native uint32, the socket's drops so far
LATE_READ_S = 1e-3  # a datagram read later than this after arrival counts in waited_over_1ms


def enable_kernel_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram's arrival (SO_TIMESTAMPNS); False where it cannot."""
    if not _ANCILLARY or not hasattr(sock, "recvmsg"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def enable_drop_count(sock: socket.socket) -> bool:
    """Ask the kernel for the socket's running drop count with each datagram (``SO_RXQ_OVFL``); False where it
    cannot (not Linux): the count is then unknown."""
    if not _ANCILLARY or not hasattr(sock, "recvmsg") or not sys.platform.startswith("linux"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
    except OSError:
        return False
    return True


class ArrivalOrder:
    """Receive times that never go back, one socket's datagrams after another.

    The kernel stamps a datagram on arrival only once timestamping is switched on system-wide, and Linux
    switches it on a moment after a socket asks (a deferred static-key change); a datagram that arrived
    in that moment is stamped when it is read instead, later than the ones that arrived after it and carry
    their true stamp. A socket hands datagrams in arrival order, so each arrived no earlier than the one
    before: a time before the previous one is raised to it (a recording's frames must be in time order).
    """

    __slots__ = ("last",)

    def __init__(self) -> None:
        self.last = -math.inf

    def __call__(self, t: float) -> float:
        if t < self.last:
            return self.last
        self.last = t
        return t


def receive(sock: socket.socket, stamped: bool, clock: Callable[[], float], own: dict,
            order: ArrivalOrder | None = None) -> tuple[bytes, tuple, float]:
    """One datagram: (data, sender, receive time in seconds); ``order`` keeps the times from going back.

    With ``stamped`` the time is the kernel's arrival stamp on the monotonic clock (the read time where the
    kernel gave none) and a read later than LATE_READ_S after arrival counts in ``own["waited_over_1ms"]``;
    otherwise it is ``clock()`` at the read. A drop count that comes with the datagram (:func:`enable_drop_count`)
    is kept in ``own["kernel_dropped"]``. Raises what the socket raises (timeouts included).
    """
    if not _ANCILLARY or not hasattr(sock, "recvmsg"):
        data, sender = sock.recvfrom(RECV_BUFFER)
        return data, sender, clock()
    data, ancillary, _, sender = sock.recvmsg(RECV_BUFFER, _ANCILLARY)
    t_read = time.monotonic() if stamped else clock()
    t = t_read
    for level, kind, payload in ancillary:
        if level != socket.SOL_SOCKET:
            continue
        if kind == SO_TIMESTAMPNS and stamped and len(payload) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(payload)
            # real-time stamp -> monotonic: the offset between the clocks, read now
            t = min(sec + nsec * 1e-9 - (time.time() - t_read), t_read)
        elif kind == SO_RXQ_OVFL and len(payload) >= _DROPS.size:
            total = own.get("kernel_dropped") or 0  # the kernel's count wraps at 2^32; ours goes on
            own["kernel_dropped"] = total + ((_DROPS.unpack_from(payload)[0] - total) & 0xFFFFFFFF)
    if stamped and t_read - t > LATE_READ_S:
        own["waited_over_1ms"] += 1
    return data, sender, t if order is None else order(t)


def watch_needle(address: str | None) -> bytes | None:
    """The bytes every OSC message to ``address`` contains (the address and its first padding byte)."""
    return None if address is None else address.encode("utf-8") + b"\x00"


def control_only(data: bytes, watched: int) -> bool:
    """Whether a datagram in which :func:`count_messages` found ``watched`` messages is one plain OSC message
    to the watched (control) address: the receiver then keeps it from the adapter, whose protocol it is not
    (a Live Link Face adapter counted it malformed, the panel showed a drop). A bundle goes on to the
    adapter, which passes over the control messages in it (:data:`~facepuppet.runtime.inputs.osc.CONTROL_ADDRESSES`)."""
    return watched > 0 and data[:1] == b"/"


def count_messages(data: bytes, address: str, needle: bytes) -> int:
    """OSC messages addressed exactly ``address`` in ``data`` (bundles unpacked); 0 for anything else.

    ``needle`` (:func:`watch_needle`) is a cheap first test: only a datagram containing it is decoded.
    A datagram that merely carries the bytes (a Live Link Face device name, a string argument) counts 0.
    """
    if needle not in data:
        return 0
    messages = osc.decode(data)
    if not messages:
        return 0
    return sum(1 for a, _ in messages if a == address)


@functools.lru_cache(maxsize=512)
def normalise_host(host: str) -> str:
    """An IP address in one canonical spelling: IPv4-mapped IPv6 (``::ffff:127.0.0.2``) as IPv4, IPv6
    compressed and lower-case; anything that is not an address is returned unchanged."""
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return host
    if ip.version == 6 and ip.ipv4_mapped is not None:
        return str(ip.ipv4_mapped)
    return str(ip)


def normalise_allow(allow: Iterable[str] | None) -> frozenset[str] | None:
    """The ``allow`` set in :func:`normalise_host` spelling (None stays None)."""
    return None if allow is None else frozenset(normalise_host(str(h)) for h in allow)


def sender_allowed(host: str, allow: frozenset[str]) -> bool:
    """Whether a sender's ``host`` is in ``allow`` (normalised: an IPv4 sender on a dual-stack socket
    arrives as ``::ffff:a.b.c.d``)."""
    return host in allow or normalise_host(host) in allow


def bind_udp(host: str, port: int, kind: str, stamps: bool = False) -> tuple[socket.socket, int]:
    """A UDP socket bound to host:port with a large receive buffer: (socket, buffer bytes granted).

    ``stamps`` asks for kernel arrival stamps before binding, so the first
    datagram is stamped too.

    Raises
    ------
    OSError
        naming the input kind and host:port when the address cannot be bound.
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER)
    except OSError:
        pass  # a smaller kernel buffer only means more drops in bursts
    rcvbuf = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    if stamps:
        enable_kernel_stamps(sock)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise OSError(exc.errno, f"cannot listen for {kind} input on {host}:{port}: "
                                 f"{exc.strerror or exc}{_bind_hint(exc.errno, host)}") from exc
    return sock, rcvbuf


def _bind_hint(code: int | None, host: str) -> str:
    """Why a bind failed, in words, by its errno."""
    if code == errno.EADDRNOTAVAIL:
        return (f" ({host} is not an address of this machine: listen on 127.0.0.1, on 0.0.0.0 for every "
                "interface, or on one of this machine's own addresses)")
    if code == errno.EADDRINUSE:
        return " (another program, or a previous run, is using this port)"
    if code == errno.EACCES:
        return " (ports below 1024 need privileges; choose a higher --listen port)"
    return ""


def bound_address(sock: socket.socket | None, host: str, port: int) -> tuple[str, int]:
    """(host, port) ``sock`` is bound to, or the requested ``host``, ``port`` while there is no socket."""
    if sock is None:
        return host, port
    bound_host, bound_port = sock.getsockname()[:2]
    return bound_host, bound_port


class UdpSource:
    """Frames from UDP datagrams decoded by ``adapter``.

    Parameters
    ----------
    adapter : object with ``kind``, ``default_port``, ``counters`` and
        ``handle(data, t_receive) -> Frame | None`` (see :mod:`facepuppet.runtime.inputs.kinds`)
    host : str, address to bind
    port : int or None, None for the adapter's default port, 0 for any free port
    allow : set of str or None, sender IP addresses accepted (None: all); IPv4-mapped IPv6 addresses
        (``::ffff:a.b.c.d``) and their IPv4 spelling match each other
    on_packet : callable(data bytes, t_receive float, sender (host, port)) or None, called on the
        receive thread (the recorder's ``put``: must not block)
    clock : callable() -> float seconds, the receive-time clock; with the default
        (``time.monotonic``) the kernel's arrival stamp is used where there is one
    watch : str or None, an OSC address: the decoded OSC messages with exactly this address (bundles
        included) in accepted datagrams are counted in :attr:`watched`
    """

    def __init__(self, adapter: InputAdapter, host: str = "127.0.0.1", port: int | None = None,
                 allow: set[str] | None = None, on_packet: Callable[[bytes, float, tuple], None] | None = None,
                 clock: Callable[[], float] = time.monotonic, watch: str | None = None) -> None:
        self.adapter = adapter
        self.host = host
        self.port = adapter.default_port if port is None else int(port)
        self.allow = normalise_allow(allow)
        self.on_packet = on_packet
        self.clock = clock
        self.watch = None if watch is None else str(watch)
        self.watched = 0  # OSC messages to ``watch`` accepted (only the receive thread writes it)
        self.last_error: BaseException | None = None
        self._own = {"packets": 0, "filtered_sender": 0, "internal_error": 0, "waited_over_1ms": 0,
                     "kernel_dropped": 0}
        self.rcvbuf_bytes = 0  # kernel receive buffer granted (getsockopt), 0 before start
        self.drops_reported = False  # whether the kernel hands its drop count (set at start)
        self._stale_dropped = 0
        self._slot: tuple[int, Frame | None] = (0, None)
        self._taken = 0
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._arrived = threading.Event()   # set by the thread on each new frame (wait_for_frame)
        self._also: tuple[threading.Event, ...] = ()  # set with it (arrival.ArrivalWaiter: several inputs)

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound; the requested ones before :meth:`start`."""
        return bound_address(self._sock, self.host, self.port)

    def start(self) -> UdpSource:
        """Bind and start the receive thread.

        Raises
        ------
        OSError
            naming host:port when the address cannot be bound (e.g. the port is busy).
        """
        if self._thread is not None:
            raise RuntimeError("UdpSource.start: already started")
        sock, self.rcvbuf_bytes = bind_udp(self.host, self.port, self.adapter.kind)
        self.drops_reported = enable_drop_count(sock)
        sock.settimeout(POLL_TIMEOUT_S)
        self._sock = sock
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"udp-{self.adapter.kind}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread (within about POLL_TIMEOUT_S) and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> UdpSource:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        sock, stop, own = self._sock, self._stop, self._own
        allow, on_packet, handle, clock, watch = self.allow, self.on_packet, self.adapter.handle, self.clock, \
            self.watch
        needle = watch_needle(watch)
        stamped = clock is time.monotonic and enable_kernel_stamps(sock)
        order = ArrivalOrder()
        while not stop.is_set():
            try:
                data, sender, t = receive(sock, stamped, clock, own, order)
            except (TimeoutError, BlockingIOError, InterruptedError):
                continue
            except OSError as exc:  # socket closed under us or a transient error (e.g. ICMP)
                if stop.is_set():
                    break
                own["internal_error"] += 1
                self.last_error = exc
                continue
            try:
                own["packets"] += 1
                if allow is not None and not sender_allowed(sender[0], allow):
                    own["filtered_sender"] += 1
                    continue
                watched = 0 if watch is None else count_messages(data, watch, needle)
                self.watched += watched
                if on_packet is not None:
                    on_packet(data, t, sender)
                if control_only(data, watched):
                    continue
                frame = handle(data, t)
                if frame is not None:
                    self._slot = (self._slot[0] + 1, frame)
                    self._arrived.set()
                    for event in self._also:
                        event.set()
            except Exception as exc:  # nothing escapes the thread
                own["internal_error"] += 1
                self.last_error = exc

    @property
    def frames_taken(self) -> int:
        """Frames completed up to the newest one :meth:`latest` handed out (0 before any)."""
        return self._taken

    def pending(self) -> bool:
        """A frame not yet taken is there (:meth:`latest` would hand it out)."""
        return self._slot[0] != self._taken

    def notify(self, event: threading.Event) -> None:
        """Also set ``event`` on each new frame (:class:`~facepuppet.runtime.inputs.arrival.ArrivalWaiter`)."""
        self._also = (*self._also, event)

    def wait_for_frame(self, timeout_s: float) -> bool:
        """Sleep until a frame not yet taken is there (True) or ``timeout_s`` passes (False)."""
        self._arrived.clear()
        if self._slot[0] != self._taken:     # arrived before the clear: no wait
            return True
        return self._arrived.wait(timeout_s) if timeout_s > 0 else False

    def latest(self, t: float | None = None) -> tuple[Frame | None, int]:
        """(newest frame not yet taken or None, frames overwritten unseen since the last call).

        ``t`` is accepted for the source interface and ignored: a live frame
        is there when it has arrived.
        """
        sequence, frame = self._slot
        if sequence == self._taken:
            return None, 0
        stale = sequence - self._taken - 1
        self._taken = sequence
        self._stale_dropped += stale
        return frame, stale

    @property
    def counters(self) -> dict[str, int]:
        """Adapter counters merged with packets, filtered_sender, internal_error, waited_over_1ms,
        kernel_dropped (None: the kernel does not say), stale_dropped, rcvbuf_bytes.

        ``internal_error`` is the sum of the adapter's and the thread's.
        """
        for _ in range(3):
            try:
                merged = dict(self.adapter.counters)
                break
            except RuntimeError:  # the adapter added a key while we copied
                continue
        else:
            merged = {}
        for name, value in self._own.items():
            merged[name] = merged.get(name, 0) + value
        if not self.drops_reported:
            merged["kernel_dropped"] = None
        merged["stale_dropped"] = self._stale_dropped
        merged["rcvbuf_bytes"] = self.rcvbuf_bytes
        return merged
