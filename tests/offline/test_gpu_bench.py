"""bench gpu on llvmpipe: the output only (its GPU figures are not times on a software rasteriser, and no speed is
asserted): every case in the JSON with finite, non-negative numbers, the renderer named and the warning given, the
picture drawn with the timer queries the picture drawn without them, the imported characters cached."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from facepuppet.runtime.bench.render import head_poses, synthetic_performance
from facepuppet.runtime.cli import main
from facepuppet.runtime.render.pass_clock import NO_CLOCK, NoClock
from facepuppet.runtime.render.renderer import FaceRenderer

from conftest import SHARED_DATA, need_shared
from facepuppet.offline import gpu_bench
from helpers.small_characters import sphere_character


def numbers(tree, keys=()):
    """(keys, value) of every number in nested objects."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from numbers(v, (*keys, k))
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool):
        yield keys, tree


@pytest.mark.gl
@pytest.mark.data
@pytest.mark.slow
def test_a_short_run_reports_every_case_with_finite_non_negative_numbers(tmp_path, capsys):
    need_shared("ict-facekit")
    need_shared("gltf", "Godette_vrm_v4.vrm")
    cache, out = tmp_path / "cache", tmp_path / "gpu.json"
    cache.mkdir()
    argv = ["bench", "gpu", "--data", str(SHARED_DATA), "--cache", str(cache), "--sizes", "64x48,96x54",
            "--frames", "3", "--warmup", "1", "--json", str(out)]
    assert main(argv) == 0
    r = json.loads(out.read_text())["results"]
    assert set(r["cases"]) == {"ict", "godette"}
    for character in r["cases"].values():
        assert set(character) == {"64x48", "96x54"}
        for size in character.values():
            assert set(size) == {"gpu", "cpu"}
            for case in size.values():
                assert case["frames"] == 3 and case["msaa"] == 4 and case["gl_error"] == "GL_NO_ERROR"
                assert case["picture_matches_unclocked"] is True
                assert {"setup", "clear", "opaque", "blended", "resolve"} <= set(case["gpu_passes_ms"])
                for key in ("gpu_frame_ms", "draw_finish_ms", "cpu_prepare_ms"):
                    assert set(case[key]) == {"median", "p99", "mean", "min"}
    found = list(numbers(r))
    assert len(found) > 2 * 2 * 2 * 30
    assert [k for k, v in found if not (math.isfinite(v) and v >= 0)] == []
    assert r["gl_renderer"] and r["egl_device"] == 0
    err = capsys.readouterr()
    assert f"bench gpu: on {r['gl_renderer']}" in err.out
    if "llvmpipe" in r["gl_renderer"]:
        assert r["software_rasteriser"] is True and "timer queries there do not time the draw" in r["warning"]
        assert "WARNING" in err.err and "software rasteriser" in err.err
        assert all(case["within_budget"] is None for c in r["cases"].values() for s in c.values()
                   for case in s.values())
    # imported into the cache, and taken from there the next time
    assert sorted(p.name for p in cache.iterdir()) == ["godette.npz", "ict.npz"]
    assert all(c["import_s"] > 0 for c in r["characters"].values())
    again = tmp_path / "again.json"
    assert main([*argv[:argv.index("--json")], "--characters", "godette", "--paths", "gpu", "--json", str(again)]) == 0
    r2 = json.loads(again.read_text())["results"]
    assert r2["characters"]["godette"]["import_s"] is None and list(r2["cases"]) == ["godette"]
    assert list(r2["cases"]["godette"]["64x48"]) == ["gpu"]


class _Sabotaged(FaceRenderer):
    """Draws a different background whenever a clock that times passes is given (what the check must catch)."""

    def submit(self, clock=NO_CLOCK):
        self.background = (0.16, 0.17, 0.19) if isinstance(clock, NoClock) else (0.9, 0.1, 0.1)
        super().submit(clock)


@pytest.mark.parametrize("cls, same", [(FaceRenderer, True), (_Sabotaged, False)])
def test_the_picture_check_tells_a_clock_that_changes_the_picture(egl_ctx, cls, same):
    character = sphere_character()
    renderer = cls(egl_ctx, character, 48, 32, path="gpu", msaa=4, log=lambda _: None)
    try:
        case = gpu_bench.measure_case(renderer, synthetic_performance(4, character.n_shapes), head_poses(4), 1)
        picture = renderer.read_pixels()
    finally:
        renderer.close()
    assert case["picture_matches_unclocked"] is same
    assert len(np.unique(picture.reshape(-1, 3), axis=0)) > 10  # a sphere drawn, not a cleared frame


@pytest.mark.parametrize("option, value, message", [
    ("--sizes", "64x", "WIDTHxHEIGHT"), ("--sizes", "9000x9000", "8192x8192"),
    ("--characters", "ict,nobody", "ict, godette"), ("--paths", "elastic", "gpu, cpu"), ("--device", "x", "auto"),
])
def test_bad_options_are_refused_naming_them(option, value, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "gpu", option, value])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert option in err and message in err


def test_a_data_kit_without_the_character_is_refused_naming_the_file(tmp_path, capsys):
    cache = tmp_path / "cache"
    cache.mkdir()
    assert main(["bench", "gpu", "--data", str(tmp_path), "--cache", str(cache), "--characters", "godette"]) == 2
    assert "gltf/Godette_vrm_v4.vrm not found" in capsys.readouterr().err
