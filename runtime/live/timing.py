"""Per-stage durations of the frame loop, summarised as p50 / p99 / max.

Durations are measured on ``time.perf_counter`` (wall time: they describe the
machine, not the replay, and play no part in determinism).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence

import numpy as np

logger = logging.getLogger(__name__)


class StageTimer:
    """Collects durations per named stage.

    Parameters
    ----------
    stages : sequence of str, stage names in the order the summary lists them
    clock : callable returning seconds (default ``time.perf_counter``)

    Use ``t = timer.now(); ...; timer.add("draw", timer.now() - t)`` on the hot
    path (no allocation beyond a list append), or ``with timer.measure("draw"):``.
    """

    def __init__(self, stages: Sequence[str] = (), clock: Callable[[], float] = time.perf_counter) -> None:
        self.now = clock
        self._samples: dict[str, list[float]] = {name: [] for name in stages}

    def add(self, stage: str, seconds: float) -> None:
        """Record one duration (seconds) for ``stage`` (created on first use)."""
        samples = self._samples.get(stage)
        if samples is None:
            samples = self._samples[stage] = []
        samples.append(seconds)

    def measure(self, stage: str) -> _Measure:
        """Context manager that adds the duration of its body to ``stage``."""
        return _Measure(self, stage)

    def samples(self, stage: str) -> np.ndarray:
        """Durations of ``stage``: ndarray of shape (n,), float64, seconds."""
        return np.asarray(self._samples.get(stage, ()), dtype=np.float64)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per stage: ``n``, ``p50_ms``, ``p99_ms``, ``max_ms``, ``mean_ms`` (NaN when no samples)."""
        out = {}
        for name, values in self._samples.items():
            a = np.asarray(values, dtype=np.float64) * 1e3
            if a.size:
                p50, p99 = np.percentile(a, [50, 99])
                out[name] = {"n": int(a.size), "p50_ms": float(p50), "p99_ms": float(p99),
                             "max_ms": float(a.max()), "mean_ms": float(a.mean())}
            else:
                nan = float("nan")
                out[name] = {"n": 0, "p50_ms": nan, "p99_ms": nan, "max_ms": nan, "mean_ms": nan}
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
