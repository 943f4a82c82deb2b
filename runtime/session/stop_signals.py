"""Ctrl-C and SIGTERM as a request to stop a session at its next tick, not as an end of the process.

A session killed where it stands leaves a recording without its end, a video without its index, a PNG half
written and no word of what was done. Within :class:`StopOnSignals` the two signals only set an event the
frame loop checks before each tick (its ``stop``); the loop then ends normally, the session's ``ExitStack``
completes every output, and the command prints its summary. The signal that asked is kept, so the summary
can say so and the exit code can be the shell's ``128 + signal``.
"""

from __future__ import annotations

import signal
import threading
from typing import Any


class StopOnSignals:
    """Within the block (main thread only; elsewhere nothing changes), SIGINT and SIGTERM set ``event``.

    Attributes
    ----------
    event : threading.Event, set by either signal
    received : signal.Signals or None, the first signal that arrived
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, event: threading.Event) -> None:
        self.event = event
        self.received: signal.Signals | None = None
        self.previous: dict[int, Any] = {}

    def _handle(self, signum: int, frame: object) -> None:
        if self.received is None:
            self.received = signal.Signals(signum)
        self.event.set()

    def __enter__(self) -> StopOnSignals:
        if threading.current_thread() is threading.main_thread():
            for signum in self.SIGNALS:
                self.previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self.previous.items():
            signal.signal(signum, previous)
        self.previous = {}
