"""Every datagram an adapter is handed, counted: decoded into a frame, dropped for a reason, or a bug.

The adapters of the phone and webcam trackers share one ``handle`` contract
(:class:`~facepuppet.runtime.protocols.InputAdapter`): never raise, count
each datagram in ``datagrams`` and then in exactly one of ``frames``, the
reason it was dropped (the adapter raises :class:`Dropped` naming its
counter), ``internal_error`` (an exception in the adapter's own code) or the
adapter's counter for a datagram that carries no frame (``none_counter``).
"""

from __future__ import annotations

from collections.abc import Callable

from facepuppet.runtime.frames import Frame


class Dropped(Exception):
    """A datagram to drop: the message is the counter to count it in."""


def counted(counters: dict[str, int], decode: Callable[[bytes, float], Frame | None], data: bytes,
            t_receive: float, max_size: int | None = None, none_counter: str | None = None) -> Frame | None:
    """``decode(data, t_receive)`` with its outcome counted (see the module doc); the frame, or None.

    ``max_size``: a datagram longer than this is dropped as ``oversized`` before decoding.
    """
    counters["datagrams"] += 1
    try:
        if max_size is not None and len(data) > max_size:
            raise Dropped("oversized")
        frame = decode(data, t_receive)
    except Dropped as bad:
        counters[str(bad)] += 1
        return None
    except Exception:  # a bug here: count it and go on
        counters["internal_error"] += 1
        return None
    if frame is not None:
        counters["frames"] += 1
    elif none_counter is not None:
        counters[none_counter] += 1
    return frame
