"""Nothing per tick is retained: stage timings in fixed memory (ring + streaming histogram), the frame loop's
memory flat over thousands of ticks (tracemalloc), percentiles still right."""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.stats import STAGES, LiveStats
from facepuppet.runtime.live.timing import DurationSketch, StageTimer

SHAPES = ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight")


class NullRenderer:
    """Draws nothing and keeps nothing (the loop's own retention is what is measured)."""

    def draw(self, weights, head_rotation=None, head_translation=None):
        pass

    def finish(self):
        pass

    def read_pixels(self):
        return np.zeros((2, 2, 3), np.uint8)


class EndlessSource:
    """A new frame every tick; with ``varying`` its channel tuple is new every tick (a sender whose channel
    set keeps changing), otherwise always the same."""

    def __init__(self, varying: bool = False):
        self.k = 0
        self.varying = varying

    def latest(self, t):
        self.k += 1
        channels = ("JawOpen", "EyeBlinkLeft", f"Extra{self.k if self.varying else 0}")
        return Frame(t=t, source="test", channels=channels, weights=[0.5 * (self.k % 2), 0.1, 0.0]), 0


def traced_after(fn) -> int:
    gc.collect()
    fn()
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


@pytest.mark.parametrize("varying", [False, True])
def test_the_frame_loop_retains_nothing_per_tick(varying):
    loop = FrameLoop(SHAPES, NullRenderer(), RecordedClock(), fps=100.0, log=lambda s: None,
                     observers=[LiveStats({}, interval_s=None, capacity=256).on_tick])
    source = EndlessSource(varying)
    loop.run(source, duration=10.0)  # warm-up: rings full, caches at their bound, the timer's rings full
    kept = {}

    def run(duration):
        kept.pop("result", None)  # only the newest run's result (and its timer) stays alive
        kept["result"] = loop.run(source, duration=duration)

    tracemalloc.start()
    try:
        base = traced_after(lambda: run(60.0))     # 6,000 ticks
        n_base = kept["result"].n_ticks
        longer = traced_after(lambda: run(120.0))  # 12,000 ticks: the same memory
    finally:
        tracemalloc.stop()
    assert kept["result"].n_ticks - n_base == 6000
    grown = longer - base
    assert grown < 32 << 10, f"{grown} bytes more after 6,000 more ticks (about {grown / 6000:.0f} B per tick)"


def test_stage_timer_keeps_a_fixed_ring_and_a_whole_run_summary():
    rng = np.random.default_rng(0)
    durations = rng.lognormal(np.log(2e-3), 0.6, size=20_000)  # seconds, ~2 ms typical
    timer = StageTimer(["draw"], capacity=1000)
    tracemalloc.start()
    try:
        for d in durations[:10_000]:
            timer.add("draw", float(d))
        gc.collect()
        half = tracemalloc.get_traced_memory()[0]
        for d in durations[10_000:]:
            timer.add("draw", float(d))
        gc.collect()
        full = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert full - half < 4096  # 10,000 more durations, no more memory
    np.testing.assert_array_equal(timer.samples("draw"), durations[-1000:])  # the recent ring, oldest first
    s = timer.summary()["draw"]
    assert s["n"] == 20_000
    assert s["max_ms"] == pytest.approx(durations.max() * 1e3)
    assert s["mean_ms"] == pytest.approx(durations.mean() * 1e3)
    for key, q in (("p50_ms", 50), ("p99_ms", 99)):
        assert s[key] == pytest.approx(np.percentile(durations, q) * 1e3, rel=0.011)  # the sketch: within 1 %
    assert s["recent_p99_ms"] == pytest.approx(np.percentile(durations[-1000:], 99) * 1e3)


def test_a_short_run_keeps_exact_percentiles():
    timer = StageTimer(["a"], capacity=1000)
    for ms in range(1, 101):
        timer.add("a", ms / 1000)
    s = timer.summary()["a"]
    assert s["p50_ms"] == pytest.approx(50.5) and s["p99_ms"] == pytest.approx(99.01)


def test_sketch_quantiles_are_within_one_percent_across_the_range():
    values = np.geomspace(2e-6, 500.0, 7919)
    sketch = DurationSketch()
    for v in values:
        sketch.add(float(v))
    sketch.add(float("nan"))  # ignored
    assert sketch.n == len(values) and sketch.max == values.max()
    for q in (0.01, 0.25, 0.5, 0.9, 0.99):
        exact = np.quantile(values, q, method="lower")
        assert sketch.quantile(q) == pytest.approx(exact, rel=0.011)
    assert np.isnan(DurationSketch().quantile(0.5))


def test_live_stats_whole_run_after_the_ring_wrapped():
    from types import SimpleNamespace

    rng = np.random.default_rng(1)
    stats = LiveStats({}, interval_s=None, capacity=128)
    e2e = []
    for _ in range(2000):
        gaps = rng.uniform(1e-4, 5e-3, size=4)
        t0 = 100.0
        stamps = (t0, t0 + gaps[0], t0 + gaps[:2].sum(), t0 + gaps[:3].sum(), t0 + gaps.sum())
        info = SimpleNamespace(raw=SimpleNamespace(t=t0 - 1e-3), stamps=stamps)
        stats.on_tick(info)
        e2e.append(stamps[4] - (t0 - 1e-3))
    whole = stats.summary()["latency_ms"]
    assert set(whole) == set(STAGES) and whole["end_to_end"]["n"] == 2000
    assert whole["end_to_end"]["p50_ms"] == pytest.approx(np.percentile(e2e, 50) * 1e3, rel=0.011)
    assert whole["end_to_end"]["max_ms"] == pytest.approx(max(e2e) * 1e3)
    assert stats.latency()["end_to_end"]["n"] == 128  # the recent window is the ring
