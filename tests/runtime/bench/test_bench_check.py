"""make bench-check's pieces: the A/B order, the medians of the rounds, and a whole sitting in a temporary clone with
a throwaway commit (real git, worktree and shims) whose benchmark runs are replaced by a stand-in writing reports,
so that what is compared, and that the base's worktree goes away after, is checked in a second, not ten minutes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from facepuppet.runtime.bench import bench_check, revision

from helpers.git_clones import throwaway_clone


@pytest.fixture(scope="module")
def clone(tmp_path_factory) -> Path:
    return throwaway_clone(tmp_path_factory.mktemp("clone"))


def test_the_sides_take_turns_round_by_round():
    assert bench_check.schedule(2, ("render", "latency")) == [
        (1, "render", "head"), (1, "render", "base"), (1, "latency", "head"), (1, "latency", "base"),
        (2, "render", "head"), (2, "render", "base"), (2, "latency", "head"), (2, "latency", "base")]


def test_the_median_of_each_number_over_the_rounds():
    rounds = [{"bench": "render", "results": {"fps": 10.0, "ms": {"p50": 3.0}, "path": "gpu", "ok": True,
                                              "series": [1, 2]}},
              {"bench": "render", "results": {"fps": 30.0, "ms": {"p50": math.nan}, "path": "cpu", "ok": False}},
              {"bench": "render", "results": {"fps": 20.0, "ms": {"p50": 5.0}, "extra": 1.0}}]
    merged = bench_check.median_report(rounds)
    assert merged == {"bench": "render", "results": {"fps": 20.0, "ms": {"p50": 4.0}, "path": "gpu", "ok": True,
                                                     "series": [1, 2]}}


def _stand_in(calls: list):
    """A ``run(shim, argv)`` that records each command and writes what it would: the character file, and bench
    reports where the working tree's draw is 30 % slower than the base's and its frames/s 10 % lower (with a
    different value each round, so that only the median matches)."""
    rounds: dict[tuple[str, str], int] = {}

    def run(shim: Path, argv: list[str]) -> None:
        side = shim.name.removeprefix("shim-")
        calls.append((side, argv[0] if argv[0] != "bench" else f"bench {argv[1]}"))
        if argv[0] == "import-rig":
            Path(argv[argv.index("-o") + 1]).write_bytes(b"")
            return
        name = argv[1]
        k = rounds[(name, side)] = rounds.get((name, side), 0) + 1
        noise = (0.9, 1.0, 1.1)[k % 3]  # the rounds 1.0, 1.1, 0.9 x: median 1.0
        slower = 1.3 if side == "head" else 1.0
        fewer = 0.9 if side == "head" else 1.0
        report = {"bench": name, "machine": {"cpu_count": 2},
                  "results": {"character": argv[argv.index("-c") + 1], "msaa": 4,
                              "draw_finish_ms": {"median": 20.0 * slower * noise, "n": 60 * k},
                              "frames_per_s": 50.0 * fewer / noise}}
        Path(argv[argv.index("--json") + 1]).write_text(json.dumps(report))

    return run


@pytest.fixture
def data_kit(tmp_path):
    obj = tmp_path / "data" / "ict-facekit" / "generic_neutral_mesh.obj"
    obj.parent.mkdir(parents=True)
    obj.write_text("v 0 0 0\n")
    return obj.parents[1]


def test_a_sitting_compares_the_medians_of_the_working_tree_with_the_base(clone, data_kit, tmp_path):
    out = tmp_path / "out"
    args = bench_check.build_parser().parse_args(["--repo", str(clone), "--data", str(data_kit), "--out", str(out),
                                                  "--rounds", "3"])
    calls, lines = [], []
    result = bench_check.run_sitting(args, run=_stand_in(calls), log=lines.append)
    assert calls[:2] == [("head", "import-rig"), ("base", "import-rig")]
    assert calls[2:] == [(side, f"bench {bench}") for _, bench, side in bench_check.schedule(3, ("render", "latency"))]
    for bench in ("render", "latency"):
        c = result["comparisons"][bench]
        assert c["flagged"] == ["draw_finish_ms.median"]  # 30 % slower: flagged; 10 % fewer frames/s: not
        figures = {f["name"]: f for f in c["figures"]}
        assert figures["draw_finish_ms.median"]["ratio"] == pytest.approx(1.3)
        assert figures["frames_per_s"]["worse_by"] == pytest.approx(0.1)
        assert c["configuration_differs"] == []  # each side's ict.npz, one file name
    assert result["base"] == revision.resolve(clone, "HEAD~1") and "HEAD~1 = " in result["base_label"]
    assert json.loads((out / "bench-check.json").read_text()) == result
    assert len(json.loads((out / "head-render-median.json").read_text())["rounds"]) == 3
    text = "\n".join(lines)
    assert "head: working tree at" in text and f"imports facepuppet.runtime from {clone.resolve()}" in text
    assert f"imports facepuppet.runtime from {(out / 'base').resolve()}" in text
    assert "<< FLAGGED" in text and "1 of 2 figures more than 20 % worse" in text
    assert not (out / "base").exists()  # the base's worktree is removed after the sitting
    assert str((out / "base").resolve()) not in revision.git(clone, "worktree", "list")


def test_a_sitting_that_cannot_run_exits_2_saying_why(clone, data_kit, tmp_path, capsys):
    common = ["--repo", str(clone), "--out", str(tmp_path / "out")]
    assert bench_check.main([*common, "--data", str(data_kit), "--base", "no-such-revision"]) == 2
    assert "no-such-revision" in capsys.readouterr().err
    assert bench_check.main([*common, "--data", str(tmp_path / "nowhere")]) == 2
    assert "ict-facekit/generic_neutral_mesh.obj not found" in capsys.readouterr().err
    assert bench_check.main([*common, "--data", str(data_kit), "--rounds", "1"]) == 2
    assert "--rounds" in capsys.readouterr().err
    assert bench_check.main([*common, "--data", str(data_kit), "--render-size", "big"]) == 2
    assert "--render-size: expected WIDTHxHEIGHT" in capsys.readouterr().err
    assert not (tmp_path / "out" / "base").exists()  # refused before anything was checked out
