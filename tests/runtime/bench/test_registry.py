"""The bench command and the render bench, end to end on a small character (no timing asserted)."""

from __future__ import annotations

import argparse
import json

import pytest

from facepuppet.runtime.bench import registry as bench

from facepuppet.offline.io.gltf.read import read_gltf
from helpers.small_characters import sphere_character
from helpers.vrm_rigs import look_at_vrm


def parse(argv):
    parser = argparse.ArgumentParser()
    bench.register(parser.add_subparsers())
    return parser.parse_args(argv)


@pytest.mark.gl
def test_bench_render_writes_json_for_both_paths(tmp_path):
    character_path = sphere_character().save(tmp_path / "sphere.npz")
    out = tmp_path / "bench.json"
    args = parse(["bench", "render", "--json", str(out), "-c", str(character_path), "--frames", "6",
                  "--width", "64", "--height", "48"])
    assert args.func(args) == 0
    report = json.loads(out.read_text())
    assert report["bench"] == "render" and report["machine"]["cpu_count"] >= 1
    results = report["results"]
    assert set(results["paths"]) == {"gpu", "cpu"} and results["auto_choice"] in ("gpu", "cpu")
    for p in results["paths"].values():
        assert p["frames"] == 6 and p["frames_per_s"] > 0
        assert p["cpu_prepare_ms"]["p99"] >= p["cpu_prepare_ms"]["median"]
    assert results["gl_error"] == "GL_NO_ERROR"
    assert all("spring_ms" not in p for p in results["paths"].values())  # no springs, no spring figure


@pytest.mark.gl
def test_bench_render_reports_the_spring_step_of_a_character_with_springs(tmp_path):
    character_path = read_gltf(look_at_vrm(tmp_path / "eyes.vrm")).save(tmp_path / "eyes.npz")
    out = tmp_path / "bench.json"
    args = parse(["bench", "render", "--json", str(out), "-c", str(character_path), "--frames", "6",
                  "--width", "64", "--height", "48"])
    assert args.func(args) == 0
    for p in json.loads(out.read_text())["results"]["paths"].values():
        assert p["spring_ms"]["median"] > 0 and p["spring_ms"]["p99"] >= p["spring_ms"]["median"]


def test_bench_lists_and_refuses_unknown_names(capsys):
    assert bench.run(argparse.Namespace(name=None, options=[])) == 0
    assert "render" in capsys.readouterr().out
    assert bench.run(argparse.Namespace(name="nope", options=[])) == 2
    assert "no benchmark named 'nope'" in capsys.readouterr().err


def test_load_average_is_three_numbers_or_n_a(monkeypatch):
    monkeypatch.setattr(bench.os, "getloadavg", lambda: (1.0, 0.5, 0.254))
    assert bench.load_average() == "1.00 0.50 0.25"

    def no_load():
        raise OSError("no load average here")

    monkeypatch.setattr(bench.os, "getloadavg", no_load)
    assert bench.load_average() == "n/a"
    monkeypatch.delattr(bench.os, "getloadavg")
    assert bench.load_average() == "n/a"


@pytest.mark.gl
@pytest.mark.slow
def test_bench_soak_runs_short_and_reports_the_rss_series_and_slope(tmp_path):
    character_path = sphere_character().save(tmp_path / "sphere.npz")
    out = tmp_path / "soak.json"
    args = parse(["bench", "soak", "--json", str(out), "-c", str(character_path), "--seconds", "8", "--cycle", "4",
                  "--sample-s", "0.5", "--size", "64x48", "--quiet"])
    assert args.func(args) == 0
    r = json.loads(out.read_text())["results"]
    assert r["seconds"] == 8.0 and r["warmup_s"] == pytest.approx(8 / 3) and r["goal_mb_per_hour"] == 1.0
    series = r["rss_mb"]
    assert len(series) >= 6 and all(p["mb"] > 0 for p in series)
    assert [p["t_s"] for p in series] == sorted(p["t_s"] for p in series)
    assert isinstance(r["rss_slope_mb_per_hour"], float) and isinstance(r["passed"], bool)
    assert r["passed"] == (r["rss_slope_mb_per_hour"] < 1.0)
    assert r["sent"]["calibrations"] == 4  # at 10 % and 90 % of each of the two cycles
    assert r["counters"]["pipeline"]["calibrations"] >= 1  # the calibrate messages reached the run
    assert r["counters"]["pipeline"]["tracking_lost"] >= 1  # the silent stretch of each cycle
    assert r["counters"]["record"]["packets_recorded"] > 0 and r["record_bytes"] > 0
    # the sender's datagrams arrive (its VMC bundles and calibrate messages)
    sent = r["sent"]["datagrams"]
    assert sent > 3 * r["sent"]["frames"]  # a status bundle and the blend bundles (<= 1,200 bytes) per frame
    assert sent / 2 < r["counters"]["udp"]["packets"] <= sent  # the last few may be unread when the run stops


@pytest.mark.gl
@pytest.mark.slow
def test_bench_soak_with_the_panel_presses_record_and_stop_each_cycle(tmp_path):
    pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")
    character_path = sphere_character().save(tmp_path / "sphere.npz")
    out = tmp_path / "soak.json"
    args = parse(["bench", "soak", "--json", str(out), "-c", str(character_path), "--seconds", "8", "--cycle", "4",
                  "--sample-s", "0.5", "--size", "320x240", "--quiet", "--panel"])
    assert args.func(args) == 0
    r = json.loads(out.read_text())["results"]
    panel = r["panel"]
    assert panel["records_started"] == panel["records_stopped"] == 2  # at 25 % and 40 % of each cycle
    assert r["counters"]["record"]["recordings"] == 3  # --record's own, then the panel's two
    assert r["counters"]["record"]["record_failed"] == 0
    assert panel["settings_builds"] >= 2  # the lost / found and calibrations changed what it shows
    assert r["counters"]["udp"]["unknown_address"] == 0  # the calibrate messages are not drops
    assert r["record_bytes"] > 0


def test_soak_slope_and_phases():
    from facepuppet.runtime.bench.soak import phase, slope_per_hour

    series = [(t, 100.0 + 2.0 * t / 3600) for t in range(0, 600, 10)]  # 2 MB per hour, exactly
    assert slope_per_hour(series, 60.0) == pytest.approx(2.0)
    assert slope_per_hour(series[:2], 0.0) != slope_per_hour(series[:2], 0.0)  # NaN: too few samples
    assert [phase(t, 60.0) for t in (0, 29.9, 30, 39.9, 40, 49.9, 50, 59.9)] == \
        ["move", "move", "idle", "idle", "loss", "loss", "move", "move"]
