"""OSC datagrams to messages, and the shared frame of an OSC input adapter.

:func:`decode` is a strict OSC 1.0 reader written for the receive thread: it
takes the types trackers send (``i h f d s b T F N``), nested bundles up to
``MAX_DEPTH`` levels, and returns None for anything malformed, never raising,
never sleeping, never logging. python-osc (:mod:`pythonosc.osc_packet`) is the
reference it is tested against (tests/runtime/inputs/test_fuzz.py checks that
on every datagram this reader accepts, python-osc reads the same messages), and
the sender side's builder. Receiving does not go through python-osc because,
measured here (1.10.2, 2-core machine): it takes about twice as long as this
reader on a 52-value VMC bundle (~0.5 ms against ~0.27 ms median); it logs a
warning through the root logger for each odd datagram; and a 20-byte bundle
whose element size is -4 makes its parser loop forever (``OscBundle._parse_contents`` steps back over the size).
Its dispatcher also sleeps on future-stamped bundles; time tags are ignored
here (messages are handled on arrival, in bundle order).

An argument of a type this reader does not know (``r m t c S I [`` ...) ends the
argument list with :data:`UNSUPPORTED` (its size is unknown), so a message
with such a trailing extra still works and one that needs the value fails the
adapter's type check; the bundle element size keeps the rest of a bundle readable.

An adapter (one per protocol module) subclasses :class:`OscAdapter` and
implements two small hooks: ``_message(address, params, t)`` per message, in
order, and ``_end_datagram(t)`` after the last message of a datagram, which
returns the completed :class:`~facepuppet.runtime.frames.Frame` or None.

Argument types: an OSC float argument (``f`` or ``d``) is accepted where a
float is expected, and so is an integer (``i``, ``h``: senders such as Max
write whole numbers as ints); booleans (``T``/``F``), strings, blobs and the
rest are wrong types. An integer argument must be an OSC integer.

Counters (:data:`COUNTER_NAMES`, all present from the start):

================  ==========================================================
datagrams         every datagram handed to :meth:`OscAdapter.handle`
frames            frames returned
malformed         one per datagram :func:`decode` refuses (empty, truncated,
                  bad type tags) and one per message with too few arguments or
                  an argument of the wrong type; extra arguments are ignored
unknown_address   messages whose address the adapter does not handle (ignored,
                  not an error: VMC receiver rules, PROTOCOLS.md §1); the
                  runtime's own control messages (:data:`CONTROL_ADDRESSES`,
                  counted by the receiver) are not among them
nonfinite         frames (or stand-alone pose messages) rejected because a
                  value was NaN or infinite
oversized         datagrams or payloads over the adapter's size limit
superseded        frames completed and overwritten within one datagram
internal_error    an exception inside the adapter's own code (a bug); the
                  datagram is dropped, the adapter goes on
================  ==========================================================
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from facepuppet.runtime.frames import Frame

COUNTER_NAMES: tuple[str, ...] = (
    "datagrams", "frames", "malformed", "unknown_address", "nonfinite",
    "oversized", "superseded", "internal_error",
)

MAX_UDP_PAYLOAD = 65507  # the largest IPv4 UDP payload
CALIBRATE_ADDRESS = "/facepuppet/calibrate"  # capture the neutral: the receivers count decoded messages to it
#: Addresses of the runtime's own control messages, sent to any input's port: the receivers count them, an
#: adapter passes over them (neither a frame's part nor an unknown address)
CONTROL_ADDRESSES = frozenset({CALIBRATE_ADDRESS})


MAX_DEPTH = 8  # nested bundle levels accepted
BUNDLE_PREFIX = b"#bundle\x00"


class _Unsupported:
    def __repr__(self) -> str:
        return "UNSUPPORTED"


#: Placeholder for an argument of a type :func:`decode` does not read (and all after it).
UNSUPPORTED = _Unsupported()

_INT = struct.Struct(">i")
_FIXED = {"i": struct.Struct(">i"), "f": struct.Struct(">f"), "d": struct.Struct(">d"), "h": struct.Struct(">q")}
_CONSTANT = {"T": True, "F": False, "N": None}


def decode(data: bytes) -> list[tuple[str, list]] | None:
    """Messages of one OSC datagram, bundles unpacked in order; None when malformed.

    Parameters
    ----------
    data : bytes, one UDP datagram

    Returns
    -------
    list of (address str, params list) or None. Malformed: empty, not starting
    with ``/`` or ``#bundle``, truncated strings, arguments or bundle elements,
    a type tag string not starting with ``,``, invalid UTF-8, element sizes
    that are negative, not a multiple of 4 or past the end, bundles nested
    deeper than MAX_DEPTH.
    """
    out: list[tuple[str, list]] = []
    try:
        ok = _element(data, 0, len(data), 0, out)
    except (struct.error, UnicodeDecodeError, ValueError, IndexError):
        return None
    return out if ok else None


def _element(data: bytes, start: int, end: int, depth: int, out: list) -> bool:
    if data.startswith(BUNDLE_PREFIX, start):
        return _bundle(data, start, end, depth, out)
    if data.startswith(b"/", start):
        message = _message(data, start, end)
        if message is None:
            return False
        out.append(message)
        return True
    return False


def _bundle(data: bytes, start: int, end: int, depth: int, out: list) -> bool:
    if depth >= MAX_DEPTH or end - start < 16:  # prefix + 8-byte time tag
        return False
    pos = start + 16
    while pos < end:
        if end - pos < 4:
            return False
        (size,) = _INT.unpack_from(data, pos)
        pos += 4
        if size <= 0 or size % 4 or pos + size > end:
            return False
        if not _element(data, pos, pos + size, depth + 1, out):
            return False
        pos += size
    return True


def _message(data: bytes, start: int, end: int) -> tuple[str, list] | None:
    find = data.find
    zero = find(b"\x00", start, end)
    if zero < 0:
        return None
    pos = start + ((zero - start) // 4 + 1) * 4
    if pos > end:
        return None
    address = data[start:zero].decode("utf-8")
    params: list = []
    if pos == end:
        return address, params
    if data[pos] != 44:  # the type tag string starts with ","
        return None
    zero = find(b"\x00", pos, end)
    if zero < 0:
        return None
    tags = data[pos + 1:zero].decode("ascii")
    pos += ((zero - pos) // 4 + 1) * 4
    if pos > end:
        return None
    append = params.append
    for tag in tags:
        fixed = _FIXED.get(tag)
        if fixed is not None:
            if pos + fixed.size > end:
                return None
            append(fixed.unpack_from(data, pos)[0])
            pos += fixed.size
        elif tag == "s":
            zero = find(b"\x00", pos, end)
            after = pos + ((zero - pos) // 4 + 1) * 4
            if zero < 0 or after > end:
                return None
            append(data[pos:zero].decode("utf-8"))
            pos = after
        elif tag == "b":
            if pos + 4 > end:
                return None
            (size,) = _INT.unpack_from(data, pos)
            after = pos + 4 + size + (-size % 4)
            if size < 0 or after > end:
                return None
            append(data[pos + 4:pos + 4 + size])
            pos = after
        elif tag in _CONSTANT:
            append(_CONSTANT[tag])
        else:
            append(UNSUPPORTED)
            break
    return address, params


def as_float(value: object) -> float | None:
    """``value`` as a float when it is an OSC float or integer argument, else None."""
    kind = type(value)
    if kind is float:
        return value
    if kind is int:
        return float(value)
    return None


def floats(params: list, start: int, n: int) -> list[float] | None:
    """``params[start:start+n]`` as floats; None when too few or any has a wrong type."""
    if len(params) < start + n:
        return None
    out = []
    for value in params[start:start + n]:
        f = as_float(value)
        if f is None:
            return None
        out.append(f)
    return out


FLOAT32_MAX = 3.4028234663852886e38


def finite32(value: float) -> bool:
    """True when ``value`` is finite and fits float32 (a double beyond it would become inf)."""
    return abs(value) <= FLOAT32_MAX


def all_finite(values: Iterable[float]) -> bool:
    """True when every value is finite and fits float32."""
    return all(abs(v) <= FLOAT32_MAX for v in values)


class OscAdapter:
    """Base of the OSC protocol adapters: datagram in, Frame (or None) out, never raises.

    Subclasses set ``kind``, ``default_port`` and implement :meth:`_message`
    and :meth:`_end_datagram`; they count per-message problems with
    :meth:`_count`.
    """

    kind: str = ""
    default_port: int = 0
    max_datagram: int = MAX_UDP_PAYLOAD

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self._pending: Frame | None = None

    def handle(self, data: bytes, t_receive: float) -> Frame | None:
        """Decode one datagram received at ``t_receive`` (seconds, monotonic).

        Returns the frame it completes, or None. Never raises, never blocks.
        """
        counters = self.counters
        counters["datagrams"] += 1
        try:
            if len(data) > self.max_datagram:
                counters["oversized"] += 1
                return None
            messages = decode(data)
            if messages is None:
                counters["malformed"] += 1
                return None
            self._pending = None
            for address, params in messages:
                if address not in CONTROL_ADDRESSES:
                    self._message(address, params, t_receive)
            end = self._end_datagram(t_receive)
            if end is not None:
                self._emit(end)
            frame, self._pending = self._pending, None
        except Exception:  # a bug in the adapter: count it, drop the datagram, go on
            counters["internal_error"] += 1
            self._pending = None
            return None
        if frame is not None:
            counters["frames"] += 1
        return frame

    def _emit(self, frame: Frame) -> None:
        """Make ``frame`` this datagram's result (an earlier one is counted as superseded)."""
        if self._pending is not None:
            self.counters["superseded"] += 1
        self._pending = frame

    def _count(self, name: str) -> None:
        self.counters[name] += 1

    def _message(self, address: str, params: list, t: float) -> None:
        raise NotImplementedError

    def _end_datagram(self, t: float) -> Frame | None:
        return None
