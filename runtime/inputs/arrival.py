"""Waking the frame loop when any of a run's inputs has a new frame, not only its own.

A live run draws on arrival (:mod:`~facepuppet.runtime.live.loop`): it sleeps in its source's
``wait_for_frame`` until a frame comes or the idle redraw is due. With several inputs (``--input vmc
--input vmc:second@39541``) the mix stage takes the others' frames at each tick, so a frame of another
input waited for the loop's own input or the idle redraw (1 / ``--fps``): a head from a second tracker
was drawn up to a frame late. :class:`ArrivalWaiter` sleeps until any of them has one.

Receivers of one kind (``--receiver`` applies to every input): thread receivers
(:class:`~facepuppet.runtime.inputs.udp.UdpSource`) set one shared event besides their own; process
receivers (:class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`) each have a channel from their
child that becomes readable when the child sends something (a frame, counters, a datagram for the recorder):
the waiter selects on all of them and asks the receivers (``pending()`` reads their channel) whether a
frame came, never reading a channel itself.
"""

from __future__ import annotations

import select
import threading
import time
from collections.abc import Sequence


class ArrivalWaiter:
    """``wait(timeout_s) -> bool``: True as soon as one of ``sources`` has a frame not yet taken, False when
    ``timeout_s`` passes first. Every source has ``pending()``; thread receivers ``notify(event)``, process
    receivers ``wake_fd`` (taken when the waiter is made: make it after the sources have started)."""

    def __init__(self, sources: Sequence[object]) -> None:
        self.sources = tuple(sources)
        if not self.sources or not all(hasattr(s, "pending") for s in self.sources):
            raise ValueError("ArrivalWaiter: every source needs pending() (a UDP receiver)")
        self._event: threading.Event | None = None
        self._fds: list[int] = []
        if all(hasattr(s, "notify") for s in self.sources):
            self._event = threading.Event()
            for s in self.sources:
                s.notify(self._event)
        elif all(getattr(s, "wake_fd", None) is not None for s in self.sources):
            self._fds = [s.wake_fd for s in self.sources]
        else:
            raise ValueError("ArrivalWaiter: the sources are neither all thread receivers nor all started "
                             "process receivers")

    def _any(self) -> bool:
        return any(s.pending() for s in self.sources)

    def wait(self, timeout_s: float) -> bool:
        if self._event is not None:
            self._event.clear()
            if self._any():  # arrived before the clear: no wait
                return True
            return self._event.wait(timeout_s) if timeout_s > 0 else False
        deadline = time.monotonic() + timeout_s
        while not self._any():  # a readable channel may carry no frame: ask again until the deadline
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            select.select(self._fds, [], [], left)
        return True
