"""``--stats``: packet counters and per-stage latency of a live run, once a second and at exit.

Stages of a frame, all on the monotonic clock (``Frame.t`` is set by the UDP
thread when the datagram arrives; the loop's stamps are ``time.perf_counter``,
which is the same clock on Linux; elsewhere the offset is measured once):

=================  =============================================================
stage              from -> to
=================  =============================================================
``receive_snap``   datagram received -> the frame loop's snapshot took it
``solve_map``      snapshot -> pipeline (filter, calibrate, ease) and map/solve done
``draw_submit``    map done -> draw call submitted
``gpu_finish``     submitted -> the GPU finished (``ctx.finish()``)
``end_to_end``     datagram received -> GPU finished
=================  =============================================================

Only ticks that took a new frame are measured (a held frame has no receive).
Samples go into a fixed ring (``capacity``, its memory taken at the start) and
a streaming histogram per stage (:class:`~facepuppet.runtime.live.timing.DurationSketch`):
nothing grows in a long run. The per-second line covers the last second; the
final report covers the whole run (exact while the ring holds every sample, from
the histograms, within 1 %, once it has wrapped).
Counters are shown as totals since the start, and on the per-second line also
with their change over the last second: ``received=1234 (+60/1 s)``. A count
the system does not report (``kernel_dropped`` where the kernel gives none) is
None, shown ``unknown`` and written ``null``, never 0.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.files.json_limits import dumps_strict
from facepuppet.runtime.inputs.capture_lag import MIC_GAUGES
from facepuppet.runtime.live.timing import DurationSketch

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

logger = logging.getLogger(__name__)

#: values that are settings or levels, not counts: shown without a change
GAUGES = frozenset({"rcvbuf_bytes"}) | MIC_GAUGES
STAGES = ("receive_snap", "solve_map", "draw_submit", "gpu_finish", "end_to_end")


class LiveStats:
    """Collect and print live counters and latencies.

    Parameters
    ----------
    counters : dict of group name -> dict of str to int, read live (e.g.
        ``{"udp": source.counters, "input": adapter.counters, "loop": loop.counters}``)
    log : callable taking one str
    interval_s : float, seconds between the periodic lines (0 or None: only at exit)
    capacity : int, latency samples kept (ring)
    clock : callable, monotonic seconds (for the periodic timing)
    """

    def __init__(self, counters: dict, log: Callable[[str], None] = logger.info, interval_s: float | None = 1.0,
                 capacity: int = 1 << 16, clock: Callable[[], float] = time.monotonic) -> None:
        self.counters = counters
        self.log = log
        self.interval_s = interval_s
        self.clock = clock
        self._samples = np.empty((len(STAGES), capacity))
        self._samples.fill(0.0)  # touched now: the resident memory does not creep up while the ring fills
        self._sketches = [DurationSketch() for _ in STAGES]
        self._n = 0  # total samples ever written
        self._window_start = 0
        self._next_report = clock() + (interval_s or 0)
        self._last_counters: dict = {}
        same = time.get_clock_info("perf_counter").implementation == time.get_clock_info("monotonic").implementation
        self._offset = 0.0 if same else time.monotonic() - time.perf_counter()
        self.ticks = 0
        #: {name: callable returning a JSON-serialisable dict}: counts other parts keep, put in the summary
        #: under that name (the marker solve's saturation)
        self.sections: dict[str, Callable[[], dict]] = {}

    def on_tick(self, info: TickInfo) -> None:
        """FrameLoop ``on_tick`` hook."""
        self.ticks += 1
        if info.raw is not None:
            t0, t1, t2, t3, t4 = info.stamps
            received = info.raw.t - self._offset
            i = self._n % self._samples.shape[1]
            s = self._samples
            s[0, i] = t1 - received
            s[1, i] = t2 - t1
            s[2, i] = t3 - t2
            s[3, i] = t4 - t3
            s[4, i] = t4 - received
            for j, sketch in enumerate(self._sketches):
                sketch.add(s[j, i])
            self._n += 1
        if self.interval_s and self.clock() >= self._next_report:
            self._next_report += self.interval_s
            now = self.counter_snapshot()
            self.log(self.line(self.latency(since=self._window_start), f"last {self.interval_s:g} s",
                               previous=self._last_counters))
            self._last_counters = now
            self._window_start = self._n

    def latency(self, since: int = 0, stages: Sequence[str] = STAGES) -> dict:
        """Per stage (of ``stages``, default all) ``{"n", "p50_ms", "p99_ms", "max_ms"}`` over samples ``since`` ..
        now (ring-limited)."""
        cap = self._samples.shape[1]
        start = max(since, self._n - cap)
        idx = np.arange(start, self._n) % cap
        out = {}
        for name in stages:
            a = self._samples[STAGES.index(name), idx] * 1e3
            if a.size:
                p50, p99 = np.percentile(a, [50, 99])
                out[name] = {"n": int(a.size), "p50_ms": float(p50), "p99_ms": float(p99), "max_ms": float(a.max())}
            else:
                out[name] = {"n": 0, "p50_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan")}
        return out

    def whole_run(self) -> dict:
        """Per stage ``{"n", "p50_ms", "p99_ms", "max_ms"}`` since the start (exact while the ring holds it all)."""
        if self._n <= self._samples.shape[1]:
            return self.latency()
        out = {}
        for name, sk in zip(STAGES, self._sketches):
            out[name] = {"n": sk.n, "p50_ms": sk.quantile(0.5) * 1e3, "p99_ms": sk.quantile(0.99) * 1e3,
                         "max_ms": sk.max * 1e3}
        return out

    def samples_ms(self, stage: str) -> np.ndarray:
        """Every kept sample of ``stage`` in ms, oldest first: ndarray of shape (n,), float64."""
        cap = self._samples.shape[1]
        idx = np.arange(max(0, self._n - cap), self._n) % cap
        return self._samples[STAGES.index(stage), idx] * 1e3

    def counter_snapshot(self) -> dict:
        return {group: dict(values) for group, values in self.counters.items()}

    def line(self, latency: dict, label: str, previous: dict | None = None) -> str:
        """One stats line: counters (totals; with ``previous``, a snapshot, also the change since it) and
        latencies over the window ``label`` names."""
        groups = []
        for group, values in self.counters.items():
            before = None if previous is None else previous.get(group, {})
            shown = []
            for k, v in values.items():
                if v is None:  # a count nobody reports here (kernel_dropped off Linux): not a 0
                    shown.append(f"{k}=unknown")
                    continue
                if not (v or k in ("received", "frames_received")):
                    continue
                item = f"{k}={v}"
                if (before is not None and isinstance(v, (int, float)) and not isinstance(v, bool)
                        and k not in GAUGES):
                    delta = v - before.get(k, 0)
                    item += f" (+{delta})" if isinstance(delta, int) else f" (+{delta:g})"
                shown.append(item)
            if shown:
                groups.append(f"{group}: {' '.join(shown)}")
        lat = " ".join(f"{name} {v['p50_ms']:.2f}/{v['p99_ms']:.2f}" for name, v in latency.items() if v["n"])
        if previous is None:
            head = f"stats ({label}): counters total"
            lat_label = "latency ms p50/p99"
        else:
            head = f"stats: counters total since start (+ change in the {label})"
            lat_label = f"latency ms p50/p99 in the {label}"
        return (f"{head}: " + " | ".join(groups)
                + (f" || {lat_label} (n={latency['end_to_end']['n']}): {lat}" if lat else ""))

    def summary(self) -> dict:
        """Counters and latency over the whole run (JSON-serialisable; NaN where nothing was measured, None
        where a count is unknown)."""
        return {"ticks": self.ticks, "counters": self.counter_snapshot(), "latency_ms": self.whole_run(),
                **{name: section() for name, section in self.sections.items()}}

    def final(self) -> list[str]:
        """The whole-run line and the JSON summary (``--stats`` at exit: the command prints them), strict JSON:
        ``null`` where nothing was measured (a latency without frames), so any JSON parser reads it."""
        return [self.line(self.whole_run(), "whole run"),
                "stats json: " + dumps_strict(self.summary(), sort_keys=True)]
