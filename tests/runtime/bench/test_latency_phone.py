"""bench latency --input ifacialmocap|vtubestudio: the sender process plays the phone and the run is fed."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from facepuppet.runtime.bench.latency import bench_latency

from helpers.small_characters import sphere_character


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ifacialmocap", "vtubestudio"])
def test_bench_latency_with_a_phone_sender(kind, tmp_path, capsys):
    path = tmp_path / "sphere.npz"
    sphere_character().save(path)
    args = SimpleNamespace(character=path, input=kind, rate=30.0, seconds=1.0, size="64x48", fps=60.0, path="auto",
                           receiver="process", draw="arrival", flood=False, verbose=False)
    results = bench_latency(args)
    decode = results["decode_us"]
    assert decode["n"] == decode["frames"] > 0 and 0 < decode["p50_us"] <= decode["p99_us"]
    nominal = results["nominal"]
    assert nominal["input"] == kind and nominal["frames_sent"] == 30
    # one datagram per phone frame (the frame class's per_frame, not VMC's several)
    assert decode["datagrams_per_frame"] == 1 and nominal["datagrams_sent"] == 30
    assert nominal["frames_decoded"] == nominal["datagrams_received"] > 0  # the run asked, the phone answered
    assert nominal["end_to_end_ms"]["n"] > 0
    assert f"latency bench [{kind}]" in capsys.readouterr().out
