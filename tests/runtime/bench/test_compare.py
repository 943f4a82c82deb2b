"""``bench render|latency --against BASELINE.json``: the figures of real bench runs, a doctored copy flagged where it
got more than 20 % worse and not where it got 10 % worse, and a baseline that cannot be read refused before the
run (no speed is asserted: the runs are short, on a small sphere)."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import pytest

from facepuppet.runtime.bench import compare

from helpers.small_characters import sphere_character


def facepuppet(*argv: str) -> subprocess.CompletedProcess:
    """The real command in a child process (its exit code and lines are what is tested)."""
    return subprocess.run([sys.executable, "-m", "facepuppet", *argv], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def sphere_path(tmp_path_factory):
    return sphere_character().save(tmp_path_factory.mktemp("sphere") / "sphere.npz")


@pytest.fixture(scope="module")
def render_report(sphere_path, tmp_path_factory):
    """The JSON a short real ``bench render`` wrote: (path, report)."""
    out = tmp_path_factory.mktemp("render") / "render.json"
    done = facepuppet("bench", "render", "-c", str(sphere_path), "--frames", "6", "--width", "64", "--height", "48",
                      "--json", str(out))
    assert done.returncode == 0, done.stderr
    return out, json.loads(out.read_text())


def doctored(report: dict, changes: dict[str, float]) -> dict:
    """A copy of ``report`` with each figure named in ``changes`` (dotted keys under results) multiplied."""
    copied = copy.deepcopy(report)
    for name, factor in changes.items():
        *parents, leaf = name.split(".")
        node = copied["results"]
        for key in parents:
            node = node[key]
        node[leaf] *= factor
    return copied


def test_directions_follow_the_names():
    assert compare.direction(("paths", "gpu", "frames_per_s")) == "higher"
    assert compare.direction(("nominal", "new_frames_drawn_per_s")) == "higher"
    assert compare.direction(("paths", "gpu", "draw_finish_ms", "median")) == "lower"
    assert compare.direction(("paths", "gpu", "passes_ms", "opaque", "p99")) == "lower"
    assert compare.direction(("nominal", "stages_ms", "gpu_finish", "p50_ms")) == "lower"
    assert compare.direction(("nominal", "cpu_stage_p99_ms", "draw_submit")) == "lower"
    assert compare.direction(("decode_us", "per_frame_p99_us")) == "lower"
    for counter in (("nominal", "end_to_end_ms", "n"), ("nominal", "end_to_end_ms", "max"), ("map_step", "max_us"),
                    ("passes_ms", "msaa"), ("decode_us", "bytes"), ("nominal", "frames_drawn"),
                    ("paths", "gpu", "peak_rss_mb"), ("nominal", "rate_hz"), ("width",)):
        assert compare.direction(counter) is None, counter


@pytest.mark.gl  # the bench's child process draws
@pytest.mark.slow
def test_render_figures_30_percent_worse_are_flagged_10_percent_not(render_report):
    path, report = render_report
    base_figures = compare.figures(report["results"])
    assert "paths.gpu.frames_per_s" in base_figures and "paths.cpu.draw_finish_ms.median" in base_figures
    worse = doctored(report, {"paths.cpu.draw_finish_ms.median": 1.3,   # a time 30 % longer
                              "paths.gpu.frames_per_s": 0.7,             # a rate 30 % lower
                              "paths.gpu.draw_finish_ms.median": 1.1,    # 10 % longer
                              "paths.cpu.frames_per_s": 0.9})            # 10 % lower
    result = compare.compare(json.loads(path.read_text()), worse, baseline_path=str(path))
    assert sorted(f.name for f in result.flagged) == ["paths.cpu.draw_finish_ms.median", "paths.gpu.frames_per_s"]
    by_name = {f.name: f for f in result.figures}
    assert by_name["paths.cpu.draw_finish_ms.median"].worse_by == pytest.approx(0.3)
    assert by_name["paths.gpu.frames_per_s"].worse_by == pytest.approx(0.3)
    assert by_name["paths.gpu.draw_finish_ms.median"].worse_by == pytest.approx(0.1)
    assert by_name["paths.cpu.frames_per_s"].ratio == pytest.approx(0.9)
    assert len(result.figures) == len(base_figures) and result.differs == []
    # better is never flagged, and the JSON a script reads carries the same flags
    better = compare.compare(report, doctored(report, {"paths.cpu.draw_finish_ms.median": 0.5,
                                                       "paths.gpu.frames_per_s": 2.0}))
    assert better.flagged == []
    written = result.to_json()
    assert written["flagged"] == [f.name for f in result.flagged]
    assert {f["name"] for f in written["figures"] if f["flagged"]} == set(written["flagged"])
    lines = "\n".join(result.lines())
    assert "paths.gpu.frames_per_s" in lines and "30.0 % worse  << FLAGGED" in lines and "10.0 % worse\n" in lines


@pytest.mark.gl
@pytest.mark.slow
def test_differing_configuration_and_figures_one_run_lacks_are_said(render_report):
    path, report = render_report
    other = copy.deepcopy(report)
    other["results"]["msaa"] = samples = report["results"]["msaa"] + 2  # differs whatever was drawn
    other["results"]["character"] = "/elsewhere/sphere.npz"  # a copy of the same file elsewhere: alike
    del other["results"]["paths"]["cpu"]
    result = compare.compare(report, other, baseline_path=str(path))
    assert result.differs == [("msaa", report["results"]["msaa"], samples)]
    assert result.only_baseline == [name for name in compare.figures(report["results"]) if ".cpu." in name]
    n = len(result.only_baseline)  # the cpu path's figures: its passes (with or without an MSAA resolve) and more
    assert n > 6 and f"  only in the baseline, not compared: {n} figures: paths.cpu." in "\n".join(result.lines())
    assert f"and {n - 6} more (the JSON lists them)" in "\n".join(result.lines())
    assert "no figure in common" in "\n".join(compare.compare(report, {"results": {}}).lines())
    assert result.lines()[1] == f"  NOT ALIKE: msaa is {samples} here, {report['results']['msaa']!r} in the baseline"
    assert result.to_json()["configuration_differs"] == [{"name": "msaa", "baseline": report["results"]["msaa"],
                                                          "this_run": samples}]


@pytest.mark.gl
@pytest.mark.slow
def test_latency_figures_30_percent_worse_are_flagged_10_percent_not(sphere_path, tmp_path):
    out = tmp_path / "latency.json"
    done = facepuppet("bench", "latency", "-c", str(sphere_path), "--seconds", "1", "--size", "64x48",
                      "--json", str(out))
    assert done.returncode == 0, done.stderr
    report = json.loads(out.read_text())
    figures = compare.figures(report["results"])
    assert figures["nominal.end_to_end_ms.p99"][1] == "lower"
    assert figures["nominal.new_frames_drawn_per_s"][1] == "higher"
    assert report["results"]["nominal"]["gl_renderer"]  # said, so that a baseline from another renderer shows
    worse = doctored(report, {"nominal.end_to_end_ms.p99": 1.3, "nominal.new_frames_drawn_per_s": 0.9})
    result = compare.compare(report, worse)
    assert [f.name for f in result.flagged] == ["nominal.end_to_end_ms.p99"]


@pytest.mark.gl
@pytest.mark.slow
def test_against_on_the_command_line_writes_the_comparison_and_exits_0_unless_fail_worse(
        render_report, sphere_path, tmp_path):
    path, report = render_report
    fast = tmp_path / "fast.json"  # a baseline 100 x faster: this run is far worse in every figure
    fast.write_text(json.dumps(doctored(report, {name: (0.01 if better == "lower" else 100.0) for name, (_, better)
                                                 in compare.figures(report["results"]).items()})))
    argv = ["bench", "render", "-c", str(sphere_path), "--frames", "4", "--width", "64", "--height", "48"]

    done = facepuppet(*argv, "--against", str(fast), "--json", str(tmp_path / "a.json"))
    assert done.returncode == 0, done.stderr  # benchmarks inform
    against = json.loads((tmp_path / "a.json").read_text())["against"]
    assert against["baseline"] == str(fast) and against["threshold"] == 0.2
    assert "paths.gpu.frames_per_s" in against["flagged"] and "paths.cpu.draw_finish_ms.median" in against["flagged"]
    assert f"against {fast}:" in done.stdout and "<< FLAGGED" in done.stdout

    done = facepuppet(*argv, "--against", str(fast), "--fail-worse")
    assert done.returncode == 1, done.stderr
    assert "figures more than 20 % worse" in done.stdout

    slow = tmp_path / "slow.json"  # a baseline 100 x slower: nothing is worse, --fail-worse passes
    slow.write_text(json.dumps(doctored(report, {name: (100.0 if better == "lower" else 0.01) for name, (_, better)
                                                 in compare.figures(report["results"]).items()})))
    done = facepuppet(*argv, "--against", str(slow), "--fail-worse", "--threshold", "50")
    assert done.returncode == 0, done.stderr
    assert "none of" in done.stdout and "more than 50 % worse" in done.stdout


@pytest.mark.parametrize("name", ["render", "latency"])
def test_a_missing_baseline_is_refused_before_the_run_naming_the_file(tmp_path, name):
    missing = tmp_path / "no-such-baseline.json"
    done = facepuppet("bench", name, "-c", str(tmp_path / "unused.npz"), "--against", str(missing))
    assert done.returncode == 2
    assert str(missing) in done.stderr and "baseline" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize("content, field", [("{not json", "not a bench's JSON"),
                                            ('{"bench": "latency", "results": {}}', "bench: expected 'render'"),
                                            ('{"bench": "render", "results": []}', "results: expected an object"),
                                            ("[1, 2]", "expected a JSON object")])
def test_a_baseline_that_is_not_a_report_of_this_bench_is_refused(tmp_path, content, field):
    bad = tmp_path / "bad.json"
    bad.write_text(content)
    done = facepuppet("bench", "render", "-c", str(tmp_path / "unused.npz"), "--against", str(bad))
    assert done.returncode == 2
    assert str(bad) in done.stderr and field in done.stderr and "Traceback" not in done.stderr


def test_a_threshold_must_be_a_positive_percentage(tmp_path):
    done = facepuppet("bench", "render", "-c", "x.npz", "--against", "x.json", "--threshold", "-5")
    assert done.returncode == 2 and "--threshold" in done.stderr and "percentage above 0" in done.stderr
