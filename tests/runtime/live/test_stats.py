"""``--stats`` lines: counters as totals and as the change over the last interval, each labelled."""

from __future__ import annotations

from facepuppet.runtime.live.loop import TickInfo
from facepuppet.runtime.live.stats import LiveStats


def test_periodic_lines_print_totals_and_the_last_second_labelled():
    now = [0.0]
    counters = {"udp": {"received": 0, "filtered_sender": 0}}
    lines: list[str] = []
    stats = LiveStats(counters, log=lines.append, interval_s=1.0, clock=lambda: now[0])
    info = TickInfo()
    for second, received in ((1, 60), (2, 60), (3, 45)):   # 60, then 60, then 45 packets in each second
        counters["udp"]["received"] += received
        now[0] = float(second)
        stats.on_tick(info)
    assert len(lines) == 3
    assert "counters total since start (+ change in the last 1 s)" in lines[0]
    assert "received=60 (+60)" in lines[0]
    assert "received=120 (+60)" in lines[1]
    assert "received=165 (+45)" in lines[2]           # the total and the last second, both there
    final = stats.final()
    assert "stats (whole run): counters total: udp: received=165" in final[0]
    assert final[1].startswith("stats json: {")


def test_a_gauge_is_shown_without_a_change():
    now = [0.0]
    counters = {"udp": {"received": 3, "rcvbuf_bytes": 8388608}}
    lines: list[str] = []
    stats = LiveStats(counters, log=lines.append, interval_s=1.0, clock=lambda: now[0])
    now[0] = 1.0
    stats.on_tick(TickInfo())
    assert "rcvbuf_bytes=8388608 |" in lines[0] + " |" and "received=3 (+3)" in lines[0]
