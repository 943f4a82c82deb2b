"""bench replay: its output only (no speed is asserted): what was drawn and written, and the times per take second.

Its claim that the default replay draws each frame of the kit's 30 Hz take once is checked against the counters
of the replay it ran: one PNG per tick, no tick without a new frame; ``--fps 60`` draws the same take twice."""

from __future__ import annotations

import json
import math

import pytest

from facepuppet.runtime.cli import main

from conftest import SHARED_DATA, need_shared


@pytest.mark.gl
@pytest.mark.data
@pytest.mark.slow
def test_a_short_run_reports_what_the_replay_drew_and_its_times(tmp_path):
    need_shared("ict-facekit")
    need_shared("tracker", "livelinkface_alex_rom_3.csv")
    cache = tmp_path / "cache"
    results = {}
    for fps in (None, 60):
        out = tmp_path / f"replay-{fps}.json"
        argv = ["bench", "replay", "--data", str(SHARED_DATA), "--cache", str(cache), "--seconds", "0.5",
                "--size", "64x48", "--json", str(out)] + (["--fps", str(fps)] if fps else [])
        assert main(argv) == 0
        results[fps] = json.loads(out.read_text())["results"]
    own, sixty = results[None], results[60]
    assert (own["ticks"], own["frames_received"], own["ticks_without_new_frame"], own["pngs"]) == (16, 16, 0, 16)
    assert "at 30 fps" in own["summary"]
    assert sixty["ticks"] == sixty["pngs"] == 31 and sixty["ticks_without_new_frame"] == 15
    for r in (own, sixty):
        assert set(r["stage_p50_ms"]) == {"snapshot", "map", "draw_submit", "gpu_finish", "sink"}
        for value in (r["wall_per_take_second_ms"], r["cpu_per_take_second_ms"], *r["stage_p50_ms"].values()):
            assert math.isfinite(value) and value >= 0
    assert (cache / "ict.npz").is_file()  # imported once, used by both
