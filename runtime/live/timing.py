"""Per-stage durations of the frame loop, summarised as p50 / p99 / max, in fixed memory.

Durations are measured on ``time.perf_counter`` (wall time: they describe the
machine, not the replay, and play no part in determinism).

A show runs for hours, so nothing here grows with the number of ticks: each
stage keeps its last ``RING`` durations (:class:`DurationRing`: the recent
window, and the exact samples of a short run) and a streaming histogram of
every duration since the start (:class:`DurationSketch`: log-spaced buckets 2 %
wide from 1 µs to 1000 s, so a quantile read from it is within 1 % of a sample
of that rank). Summaries are exact while the ring still holds every sample and
come from the sketch once it has wrapped.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

logger = logging.getLogger(__name__)

RING = 4096  # recent durations kept per stage (about a minute of a 60 fps loop)
SKETCH_LO_S, SKETCH_HI_S, SKETCH_RATIO = 1e-6, 1e3, 1.02


class DurationSketch:
    """Every duration since the start, in a fixed histogram of log-spaced buckets.

    ``n``, ``max`` and ``total`` are exact; :meth:`quantile` is the geometric
    middle of the bucket holding the rank, within 1 % of a sample of that rank
    (values outside 1 µs .. 1000 s fall in the end buckets).
    """

    __slots__ = ("counts", "n", "total", "max", "_scale")

    N_BUCKETS = int(math.ceil(math.log(SKETCH_HI_S / SKETCH_LO_S) / math.log(SKETCH_RATIO))) + 1

    def __init__(self) -> None:
        self.counts = np.zeros(self.N_BUCKETS, dtype=np.int64)
        self.n, self.total, self.max = 0, 0.0, -math.inf
        self._scale = 1.0 / math.log(SKETCH_RATIO)

    def add(self, seconds: float) -> None:
        """Count one duration (seconds); NaN is ignored."""
        if not seconds >= 0.0:  # NaN or negative (a clock step): the lowest bucket for negatives, none for NaN
            if seconds != seconds:
                return
            seconds = 0.0
        i = 0 if seconds <= SKETCH_LO_S else min(self.N_BUCKETS - 1, int(math.log(seconds / SKETCH_LO_S)
                                                                         * self._scale) + 1)
        self.counts[i] += 1
        self.n += 1
        self.total += seconds
        if seconds > self.max:
            self.max = seconds

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (0..1) in seconds, NaN when empty."""
        if self.n == 0:
            return math.nan
        rank = q * (self.n - 1)
        i = int(np.searchsorted(np.cumsum(self.counts), rank, side="right"))
        if i == 0:
            return SKETCH_LO_S
        return min(SKETCH_LO_S * SKETCH_RATIO ** (i - 0.5), self.max)


class DurationRing:
    """The last ``capacity`` durations (seconds), oldest overwritten first."""

    __slots__ = ("values", "n")

    def __init__(self, capacity: int = RING) -> None:
        if capacity < 1:
            raise ValueError(f"DurationRing capacity: expected >= 1, got {capacity!r}")
        self.values = np.zeros(int(capacity), dtype=np.float64)
        self.n = 0  # written in all

    def add(self, seconds: float) -> None:
        self.values[self.n % len(self.values)] = seconds
        self.n += 1

    def recent(self) -> np.ndarray:
        """The kept durations, oldest first: ndarray of shape (min(n, capacity),), float64, seconds."""
        cap = len(self.values)
        if self.n <= cap:
            return self.values[:self.n].copy()
        i = self.n % cap
        return np.concatenate([self.values[i:], self.values[:i]])

    @property
    def complete(self) -> bool:
        """True while every duration ever added is still kept."""
        return self.n <= len(self.values)


def _stats_ms(a: np.ndarray) -> dict[str, float]:
    a = a * 1e3
    if not a.size:
        nan = float("nan")
        return {"n": 0, "p50_ms": nan, "p99_ms": nan, "max_ms": nan, "mean_ms": nan}
    p50, p99 = np.percentile(a, [50, 99])
    return {"n": int(a.size), "p50_ms": float(p50), "p99_ms": float(p99), "max_ms": float(a.max()),
            "mean_ms": float(a.mean())}


class StageTimer:
    """Collects durations per named stage, in fixed memory (see the module docstring).

    Parameters
    ----------
    stages : sequence of str, stage names in the order the summary lists them
    clock : callable returning seconds (default ``time.perf_counter``)
    capacity : int, recent durations kept per stage

    Use ``t = timer.now(); ...; timer.add("draw", timer.now() - t)`` on the hot
    path (no allocation that stays), or ``with timer.measure("draw"):``.
    """

    def __init__(self, stages: Sequence[str] = (), clock: Callable[[], float] = time.perf_counter,
                 capacity: int = RING) -> None:
        self.now = clock
        self.capacity = int(capacity)
        self._rings: dict[str, DurationRing] = {}
        self._sketches: dict[str, DurationSketch] = {}
        for name in stages:
            self._stage(name)

    def _stage(self, name: str) -> tuple[DurationRing, DurationSketch]:
        ring = self._rings[name] = DurationRing(self.capacity)
        sketch = self._sketches[name] = DurationSketch()
        return ring, sketch

    def add(self, stage: str, seconds: float) -> None:
        """Record one duration (seconds) for ``stage`` (created on first use)."""
        ring = self._rings.get(stage)
        if ring is None:
            ring, sketch = self._stage(stage)
        else:
            sketch = self._sketches[stage]
        ring.add(seconds)
        sketch.add(seconds)

    def measure(self, stage: str) -> _Measure:
        """Context manager that adds the duration of its body to ``stage``."""
        return _Measure(self, stage)

    def samples(self, stage: str) -> np.ndarray:
        """The recent durations of ``stage`` (the last ``capacity``), oldest first: ndarray (n,), float64, s."""
        ring = self._rings.get(stage)
        return np.zeros(0) if ring is None else ring.recent()

    def summary(self) -> dict[str, dict[str, float]]:
        """Per stage since the start: ``n``, ``p50_ms``, ``p99_ms``, ``max_ms``, ``mean_ms`` (NaN when no
        samples; exact while the ring holds them all, from the sketch after), and ``recent_p50_ms``,
        ``recent_p99_ms`` over the last ``capacity`` durations."""
        out = {}
        for name, ring in self._rings.items():
            recent = _stats_ms(ring.recent())
            if ring.complete:
                s = dict(recent)
            else:
                sk = self._sketches[name]
                s = {"n": sk.n, "p50_ms": sk.quantile(0.5) * 1e3, "p99_ms": sk.quantile(0.99) * 1e3,
                     "max_ms": sk.max * 1e3, "mean_ms": sk.total / sk.n * 1e3}
            s["recent_p50_ms"], s["recent_p99_ms"] = recent["p50_ms"], recent["p99_ms"]
            out[name] = s
        return out

    def table(self) -> str:
        """The summary as a fixed-width text table, one line per stage."""
        rows = [f"{'stage':<14}{'n':>7}{'p50 ms':>10}{'p99 ms':>10}{'max ms':>10}{'mean ms':>10}"]
        for name, s in self.summary().items():
            rows.append(f"{name:<14}{s['n']:>7}{s['p50_ms']:>10.3f}{s['p99_ms']:>10.3f}"
                        f"{s['max_ms']:>10.3f}{s['mean_ms']:>10.3f}")
        return "\n".join(rows)

    def print_summary(self, log: Callable[[str], None] = logger.info) -> None:
        log(self.table())


class _Measure:
    __slots__ = ("timer", "stage", "start")

    def __init__(self, timer: StageTimer, stage: str):
        self.timer = timer
        self.stage = stage

    def __enter__(self):
        self.start = self.timer.now()
        return self

    def __exit__(self, *exc):
        self.timer.add(self.stage, self.timer.now() - self.start)
