"""The fresh-process card runs: each run is a new interpreter whose result is read back, and the summary
takes the median of the runs' medians and the worst p99; without pulseaudio each run says why."""

from __future__ import annotations

import math

from facepuppet.offline.voice.card_runs import main, summarise


def _run(median: float, p99: float, dropped: int) -> dict:
    lat = {"median_ms": median, "p99_ms": p99, "n": 3}
    return {"available": True, "onsets": 3, "detected": {"arrived": 3, "drawn": 3}, "played_to_drawn": lat,
            "played_to_arrived": lat, "arrived_to_drawn": {"median_ms": math.nan, "p99_ms": math.nan, "n": 0},
            "capture": {"capture_backlog_ms": {"median": 1.0, "max": 12.4}},
            "microphone": {"blocks": 100, "stale_dropped": dropped}}


def test_the_summary_is_the_median_of_medians_and_the_worst_p99():
    s = summarise([_run(10.0, 20.0, 0), _run(30.0, 90.0, 5), _run(20.0, 25.0, 1),
                   {"available": False, "reason": "x"}])
    assert (s["runs"], s["measured"]) == (4, 3)
    assert s["played_to_drawn"] == {"median_of_medians_ms": 20.0, "worst_p99_ms": 90.0}
    assert math.isnan(s["arrived_to_drawn"]["median_of_medians_ms"])
    assert s["onsets_drawn"] == ["3/3"] * 3 and s["capture_backlog_max_ms"] == [12] * 3
    assert [m["stale_dropped"] for m in s["microphone"]] == [0, 5, 1]


def test_without_pulseaudio_each_fresh_run_says_why(tmp_path, monkeypatch, capsys):
    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    out = tmp_path / "runs.json"
    assert main([str(tmp_path / "voice.npz"), "--runs", "2", "--onsets", "1", "--json", str(out)]) == 0
    said = capsys.readouterr().out
    assert said.count("not measured (pulseaudio not installed") == 2, said
    assert out.exists()
