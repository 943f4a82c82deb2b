"""How far a microphone's blocks lie behind the capture clock, and which are too stale to read.

PortAudio stamps each callback with ``time_info``: ``inputBufferAdcTime`` (when the block's first sample was
captured) and ``currentTime`` (now), on one clock. Their difference is the block's lag: the device's and the
audio system's own standing latency, plus any backlog a callback kept from running has left queued (a busy
machine, or the main thread holding the GIL through a long C call: the audio system keeps the samples instead
of dropping them, and reading them late moves the mouth seconds after the voice).

:class:`CaptureLag` keeps a *floor*, the standing latency: it follows a lower lag at once and rises by at
most :data:`FLOOR_RISE` seconds per second of audio (a stall's backlog, which comes at once, does not become
the floor; a latency that drifts up, as a loaded PulseAudio's does by ~100 ms over a second or so, does: a
slower rise, 0.05 s per s, dropped about half the blocks of fresh runs under load for no gain), and never
above :data:`FLOOR_CAP_S`. A block is stale when its lag exceeds the floor by more than
``max_lag_s`` (:data:`MAX_LAG_S`): the voice never reads a block more than ``max_lag_s`` behind the
standing latency, nor more than ``FLOOR_CAP_S + max_lag_s`` behind the capture clock in all. A standing
latency cannot be shortened by dropping (the samples arrive no sooner), so it is forgiven up to the cap; a
backlog is dropped unread. Dropping cannot make the callback run more often, but it keeps the voice current
and costs nothing per block. Hosts that give no times (``inputBufferAdcTime`` 0) drop nothing.

:meth:`CaptureLag.fresh` runs in the audio callback: it writes integers in place into a preallocated array
and allocates nothing beyond NumPy scalars; the stats read them through :class:`MicCounters`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Mapping
from typing import Protocol

import numpy as np

logger = logging.getLogger(__name__)

MAX_LAG_S = 0.06  # a block further than this behind the standing latency is stale
FLOOR_CAP_S = 0.1  # the most standing latency forgiven: no block is read further behind than cap + max lag
FLOOR_RISE = 0.25  # the floor rises by at most this many seconds per second of audio

# blocks the callback received, read, dropped as stale and PortAudio flagged (an overflow); the largest lag
# (ms) of a block read and of one dropped; the standing latency and the bound (ms) now. The last four are
# gauges, not counts.
MIC_COUNTERS = ("blocks", "read", "stale_dropped", "status_errors", "max_read_lag_ms", "max_stale_lag_ms",
                "floor_ms", "bound_ms")
MIC_GAUGES = frozenset(MIC_COUNTERS[4:])
BLOCKS, READ, STALE, STATUS, READ_LAG, STALE_LAG, FLOOR, BOUND = range(len(MIC_COUNTERS))


class StreamTimes(Protocol):
    """The part of PortAudio's callback ``time_info`` read here (seconds on the stream's clock)."""

    inputBufferAdcTime: float  # noqa: N815 (PortAudio's name)
    currentTime: float  # noqa: N815


class MicCounters(Mapping):
    """The microphone's counters as the stats read them (``--stats``, the run's summary): a live view of the
    integers the callback writes in place, so the callback never builds a dict."""

    def __init__(self, values: np.ndarray) -> None:
        self._values = values

    def __getitem__(self, key: str) -> int:
        return int(self._values[MIC_COUNTERS.index(key)])

    def __iter__(self) -> Iterator[str]:
        return iter(MIC_COUNTERS)

    def __len__(self) -> int:
        return len(MIC_COUNTERS)


class CaptureLag:
    """The lag of each block of one stream and whether it is fresh enough to read (see the module docstring).

    Parameters
    ----------
    sample_rate : float, Hz
    max_lag_s : float, seconds a block may lie behind the standing latency (> 0)
    floor_s : float, the standing latency to start from (the stream's stated input latency), seconds
    name : str, the device, for the one log line
    """

    def __init__(self, sample_rate: float, max_lag_s: float = MAX_LAG_S, floor_s: float = 0.0,
                 name: str = "the microphone") -> None:
        if not (math.isfinite(max_lag_s) and max_lag_s > 0):
            raise ValueError(f"max_lag_s: expected a positive number, got {max_lag_s!r}")
        self.sample_rate = float(sample_rate)
        self.max_lag_s = float(max_lag_s)
        self.floor_s = min(max(float(floor_s), 0.0), FLOOR_CAP_S) if math.isfinite(floor_s) else 0.0
        self.name = name
        self.values = np.zeros(len(MIC_COUNTERS), np.int64)
        self.counters = MicCounters(self.values)
        self.values[FLOOR] = int(self.floor_s * 1000.0)
        self.values[BOUND] = int(self.bound_s * 1000.0)
        self._said = False

    @property
    def bound_s(self) -> float:
        """The lag beyond which a block is dropped now: the standing latency plus ``max_lag_s``."""
        return self.floor_s + self.max_lag_s

    def fresh(self, time_info: StreamTimes, frames: int, status: object = None) -> bool:
        """Count one block (``time_info`` as PortAudio's callback gets it) and say whether to read it."""
        values = self.values
        values[BLOCKS] += 1
        if status:
            values[STATUS] += 1
        adc = time_info.inputBufferAdcTime
        if not adc > 0.0:  # a host API that gives no times: nothing to judge by
            values[READ] += 1
            return True
        lag = time_info.currentTime - adc
        if lag < self.floor_s:
            self.floor_s = max(lag, 0.0)
        else:
            self.floor_s = min(self.floor_s + FLOOR_RISE * frames / self.sample_rate, FLOOR_CAP_S)
        bound = self.floor_s + self.max_lag_s
        values[FLOOR] = int(self.floor_s * 1000.0)
        values[BOUND] = int(bound * 1000.0)
        if lag > bound:
            values[STALE] += 1
            if lag * 1000.0 > values[STALE_LAG]:
                values[STALE_LAG] = int(lag * 1000.0)
            if not self._said:
                self._said = True
                logger.warning("%s: a block arrived %.0f ms behind the capture clock (bound %.0f ms); stale blocks "
                               "are dropped so the voice does not lag (counted as stale_dropped)",
                               self.name, lag * 1000.0, bound * 1000.0)
            return False
        values[READ] += 1
        if lag * 1000.0 > values[READ_LAG]:
            values[READ_LAG] = int(lag * 1000.0)
        return True
