"""The bench command and the render bench, end to end on a small character (no timing asserted)."""

from __future__ import annotations

import argparse
import json

import pytest

from facepuppet.runtime.bench import registry as bench

from helpers.small_characters import sphere_character


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
