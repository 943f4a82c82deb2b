"""``bench video`` end to end on small frames (no timing asserted: the figures are the bench's output)."""

from __future__ import annotations

import argparse
import json

import pytest

from facepuppet.runtime.bench import registry as bench

pytest.importorskip("av", reason="PyAV is not installed: pip install -e '.[video]' (make setup installs it)")


@pytest.mark.gl
def test_bench_video_writes_encode_and_replay_figures(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    bench.register(parser.add_subparsers())
    out = tmp_path / "video.json"
    args = parser.parse_args(["bench", "video", "--json", str(out), "--size", "64x48", "--frames", "6",
                              "--alpha", "--seconds", "0.2"])
    assert args.func(args) == 0
    results = json.loads(out.read_text())["results"]
    assert [e["codec"] for e in results["encode"]] == ["libx264", "libvpx-vp9", "prores_ks"]
    assert results["encode"][0]["frames"] == 6 and results["encode"][1]["frames"] == 10
    for e in results["encode"]:
        assert e["write_ms"]["n"] == e["frames"] and e["write_ms"]["p99"] >= e["write_ms"]["p50"] > 0
    replay = results["replay"]
    assert replay["with_video"]["ticks"] == replay["without_video"]["ticks"] == 12
    assert "ticks/s without --video" in capsys.readouterr().out
