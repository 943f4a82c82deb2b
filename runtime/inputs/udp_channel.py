"""The channel from the receiving process (:mod:`~facepuppet.runtime.inputs.udp_child`) to
:class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`: one Unix stream socket pair.

Why the kernel carries everything: the child writes while the parent reads, on different CPUs. On a weakly
ordered CPU (ARM: a Raspberry Pi, an Apple-silicon Linux box) plain stores into shared memory may become
visible to the other CPU in any order, so a reader checking a sequence number can see the new number
beside old weights; Python offers no memory barrier to forbid that. Here nothing is shared: the newest
frame, the names it uses, the counters, the error log and the recorder's datagrams all cross as bytes.
``send`` copies them into a kernel buffer and queues it on the socket under the socket's lock; ``recv``
takes it off under the same lock and copies out. The lock's release and acquire order the copy in before
the copy out on every CPU the kernel runs on, and a stream socket delivers in the order sent: once the
parent holds a message whole, every byte of it, and of everything sent before it, is what the child wrote.
The same socket wakes the parent (it becomes readable) and tells the child to stop (the parent sends a
byte) or that the parent is gone (end of file).

Why a stream and not datagrams: a message (a marker layout's names, a 64 KiB datagram for the recorder) can
be larger than a datagram socket takes in one piece, and ``socket.socketpair()`` gives a stream everywhere.
A send the socket takes only in part is finished later (:class:`Outbox`); the child never blocks on the
parent.

Messages: ``u32 body length | u8 kind | body`` (:data:`HEAD`), little-endian, kinds:

* ``READY``: the child runs (empty body);
* ``FRAME``: one decoded frame (:data:`FRAME_HEAD`, then the definitions of names new to the parent, then
  float32 weights and markers); names (channel tuples, marker names, the source) are slots of a table of
  MAX_NAMES both sides keep alike: a frame defines a name in the message that first uses it, evicting the
  least recently used one, so a new marker layout always gets in and the table never grows;
* ``PACKET``: one accepted datagram for the recorder (:data:`PACKET_HEAD`, the sender's host, the bytes);
* ``COUNTERS``: int64 values, the watched count first, then the counters by index;
* ``COUNTER_NAME``: u32 index, the counter's name (UTF-8); ``ERROR``: one error's text (UTF-8).

Bounds (the child decodes strangers' datagrams): a frame has at most MAX_WEIGHTS weights and MAX_MARKERS
markers, a name record at most MAX_NAME_RECORD bytes, there are at most MAX_COUNTERS counters, counter names
and errors together take at most META_BYTES (and at most MAX_ERRORS_LOGGED errors), datagrams waiting for
the recorder at most the receiver's ``ring_bytes`` on each side; the parent refuses a message over
MAX_MESSAGE.
"""

from __future__ import annotations

import collections
import json
import math
import socket
import struct
import time
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.frames import Frame

MAX_WEIGHTS = 1024
MAX_MARKERS = 2048
MAX_COUNTERS = 64
MAX_NAMES = 256  # name slots (channel tuples, marker layouts, sources) both sides keep
MAX_NAME_RECORD = 1 << 18  # a bigger name record (4 + its JSON) is refused (counted names_too_large)
META_BYTES = 1 << 18  # counter names and errors, in all
MAX_ERRORS_LOGGED = 100  # the child reports at most this many errors
RING_BYTES = 4 << 20  # default bound on the datagrams waiting for the recorder (each side)
MAX_MESSAGE = 1 << 20  # a frame with three new names of MAX_NAME_RECORD is under it
CHUNK = 1 << 16  # the child hands the socket at most about this much per send
RECV_BYTES = 1 << 18  # the parent's read size
FLUSH_DELAY_S = 0.005  # counters, errors and datagrams without a frame wait this long to go in one send

HEAD = struct.Struct("<IB")  # body length, kind
READY, FRAME, PACKET, COUNTERS, COUNTER_NAME, ERROR = range(1, 7)
# completed, number, watched, flags, n_weights, n_markers, t, t_sender, audio_level, pose (rotation 4,
# translation 3), name slots (channels, marker names, source; -1: none), lengths of the names defined here
FRAME_FIELDS = struct.Struct("<qqqBII3d7f")  # packed when the frame is queued (what could fail, fails there)
FRAME_NAMES = struct.Struct("<3i3I")  # packed when it is sent
FRAME_HEAD = struct.Struct(FRAME_FIELDS.format + FRAME_NAMES.format[1:])
COMPLETED, NUMBER, WATCHED, FLAGS, N_WEIGHTS, N_MARKERS, T, T_SENDER, AUDIO_LEVEL = range(9)
POSE, SLOTS, LENGTHS = slice(9, 16), slice(16, 19), slice(19, 22)
HAS_WEIGHTS, HAS_MARKERS, HAS_ROTATION, HAS_TRANSLATION = 1, 2, 4, 8
NAME_FIELDS = ("channels", "markers", "source")  # a frame's names, in the order of FRAME_HEAD's slots
PACKET_HEAD = struct.Struct("<dHB")  # receive time, sender port, sender host length
INDEX = struct.Struct("<I")


def message(kind: int, body: bytes = b"") -> bytes:
    """One message: header and body."""
    return HEAD.pack(len(body), kind) + body


def packet_cost(host_len: int, data_len: int) -> int:
    """What one waiting datagram counts against ``ring_bytes``: a 16-byte record header, the sender's host and
    the bytes, rounded up to 16 (so a ring of ``ring_bytes`` holds as many datagrams on either side)."""
    return (16 + host_len + data_len + 15) & ~15


class ChannelError(RuntimeError):
    """The channel's bytes are not the messages the child sends (a message over MAX_MESSAGE, a name slot
    never defined): the receiver's own bug, never the sender's."""


def read_frame(body: bytes, table: list) -> tuple[tuple, list, int]:
    """A FRAME message's header, its names and where its arrays start. The names it defines are entered in
    ``table`` (the child's MAX_NAMES slots, kept alike here) first.

    Raises
    ------
    ChannelError
        when a name is defined in the wrong field or a slot used was never defined.
    """
    head = FRAME_HEAD.unpack_from(body)
    off = FRAME_HEAD.size
    for field, slot, length in zip(NAME_FIELDS, head[SLOTS], head[LENGTHS]):
        if length:
            kind, value = json.loads(body[off:off + length])
            if kind != field or not 0 <= slot < MAX_NAMES:
                raise ChannelError(f"receiver channel: name slot {slot} defined as {kind!r}, expected {field!r}")
            table[slot] = tuple(value) if isinstance(value, list) else value
            off += length
    names = []
    for field, slot in zip(NAME_FIELDS, head[SLOTS]):
        if slot != -1 and (not 0 <= slot < MAX_NAMES or table[slot] is None):
            raise ChannelError(f"receiver channel: a frame names its {field} by slot {slot}, never defined")
        names.append(None if slot == -1 else table[slot])
    return head, names, off


def frame_from(head: tuple, names: list, body: bytes, off: int) -> Frame:
    """The :class:`Frame` of a message :func:`read_frame` read (arrays copied out of ``body``)."""
    flags, n_weights, n_markers = head[FLAGS], head[N_WEIGHTS], head[N_MARKERS]
    weights = np.frombuffer(body, "<f4", n_weights, off).copy() if flags & HAS_WEIGHTS else None
    off += 4 * n_weights
    markers = (np.frombuffer(body, "<f4", 3 * n_markers, off).reshape(n_markers, 3).copy()
               if flags & HAS_MARKERS else None)
    pose = np.array(head[POSE], dtype=np.float32)
    return Frame(t=head[T], source=names[2], channels=names[0], weights=weights,
                 head_rotation=pose[:4] if flags & HAS_ROTATION else None,
                 head_translation=pose[4:7] if flags & HAS_TRANSLATION else None, audio_level=head[AUDIO_LEVEL],
                 markers=markers, marker_names=names[1], t_sender=head[T_SENDER], number=head[NUMBER])


class Outbox:
    """The child's side: messages queued in the order the parent must read them, sent without blocking.

    Datagrams for the recorder, counter names and errors are kept (datagrams up to ``packet_bytes``, then
    dropped and counted by the caller); of the frames only the newest not yet sent waits, after everything
    queued before it (an older one is dropped: the parent counts it stale from the ``completed`` numbers);
    the counters go last, encoded when sent, so they never count a frame or datagram the parent has not
    read before them. ``encode_frame`` and ``encode_counters`` build those two when their turn comes (the
    names a frame defines depend on what was sent before it).

    A frame asks to be sent at once; anything else waits up to FLUSH_DELAY_S for company (VMC sends four
    datagrams per frame: their counters go with the frame, the parent wakes once).
    """

    def __init__(self, chan: socket.socket, packet_bytes: int, encode_frame: Callable[[object], bytes],
                 encode_counters: Callable[[], bytes]) -> None:
        self.chan = chan
        self.packet_bytes = packet_bytes
        self.encode_frame, self.encode_counters = encode_frame, encode_counters
        self.queue: collections.deque[tuple[bytes, int]] = collections.deque()  # (message, packet cost)
        self.queued = self.committed = 0  # messages ever put in / taken out of the queue
        self.waiting_packet_bytes = 0
        self.frame: tuple[int, object] | None = None  # (messages queued before it, what encode_frame takes)
        self.counters_due = False
        self.due_at = math.inf  # when what waits must go even without a frame
        self.out = b""  # bytes taken from the queue, being sent
        self.sent = 0

    def put(self, data: bytes, packet_cost: int = 0) -> bool:
        """Queue a message that must arrive (``packet_cost`` > 0: a datagram, refused with False when the
        datagrams waiting would pass ``packet_bytes``)."""
        if packet_cost and self.waiting_packet_bytes + packet_cost > self.packet_bytes:
            return False
        self.queue.append((data, packet_cost))
        self.queued += 1
        self.waiting_packet_bytes += packet_cost
        self._due()
        return True

    def put_frame(self, frame: object) -> None:
        """Queue the newest frame (replacing one not yet sent); it asks to be sent at once."""
        self.frame = (self.queued, frame)
        self.due_at = 0.0

    def put_counters(self) -> None:
        """The counters changed: send them after everything queued."""
        self.counters_due = True
        self._due()

    def _due(self) -> None:
        if self.due_at == math.inf:
            self.due_at = time.monotonic() + FLUSH_DELAY_S

    @property
    def blocked(self) -> bool:
        """The socket took only part of what was sent: the rest goes when it is writable again."""
        return self.sent < len(self.out)

    @property
    def empty(self) -> bool:
        return not self.blocked and not self.queue and self.frame is None and not self.counters_due

    def _take(self) -> bytes:
        """The next bytes to send, in order: queued messages, the frame at its place, the counters last."""
        parts, size = [], 0
        while size < CHUNK:
            if self.frame is not None and self.frame[0] <= self.committed:
                part = self.encode_frame(self.frame[1])
                self.frame = None
            elif self.queue:
                part, cost = self.queue.popleft()
                self.committed += 1
                self.waiting_packet_bytes -= cost
            elif self.counters_due:
                part = self.encode_counters()
                self.counters_due = False
            else:
                break
            parts.append(part)
            size += len(part)
        return b"".join(parts)

    def flush(self) -> bool:
        """Send what the socket takes now; True when nothing is left. Raises OSError when the parent is gone."""
        while True:
            if not self.blocked:
                self.out, self.sent = self._take(), 0
                if not self.out:
                    self.due_at = math.inf
                    return True
            try:
                self.sent += self.chan.send(memoryview(self.out)[self.sent:])
            except (BlockingIOError, InterruptedError):
                return False


class Inbox:
    """The parent's side: what the socket holds, read without blocking and cut into whole messages.

    A message cut short by the socket waits for its rest. After a :class:`ChannelError` the stream cannot be
    resynchronised: what comes is read and dropped, so the socket never stays readable.
    """

    def __init__(self, chan: socket.socket) -> None:
        self.chan = chan
        self.buf = bytearray()
        self.broken = False

    def read(self, limit: int = 16 * MAX_MESSAGE) -> list[tuple[int, bytes]]:
        """The whole messages arrived since the last call, in order, as (kind, body); at most about ``limit``
        bytes are read (a sender faster than this reader cannot keep it here).

        Raises
        ------
        ChannelError
            once, when the bytes are not messages (the messages before are lost with them).
        """
        got = 0
        while got < limit:
            try:
                data = self.chan.recv(RECV_BYTES)
            except (BlockingIOError, InterruptedError):
                break
            if not data:  # the other end is closed everywhere: nothing more will come
                break
            got += len(data)
            if not self.broken:
                self.buf += data
            if len(data) < RECV_BYTES:  # the socket is empty: no need to ask again
                break
        if len(self.buf) < HEAD.size:  # the common case between frames: nothing
            return []
        messages, bad = [], None
        n, off = len(self.buf), 0
        with memoryview(self.buf) as view:
            while n - off >= HEAD.size:
                length, kind = HEAD.unpack_from(view, off)
                if length > MAX_MESSAGE:
                    bad = length, kind
                    break
                end = off + HEAD.size + length
                if end > n:
                    break
                messages.append((kind, bytes(view[off + HEAD.size:end])))
                off = end
        if bad is not None:
            self.broken, self.buf = True, bytearray()
            raise ChannelError(f"receiver channel: a message of {bad[0]} bytes (kind {bad[1]}), over {MAX_MESSAGE}")
        del self.buf[:off]
        return messages
