"""bench latency --input: each kind's bench sender makes datagrams its adapter decodes, and the decode-cost
measurement runs every datagram through ``handle`` (no speed is asserted: that is the bench's job)."""

from __future__ import annotations

import argparse

import pytest

from facepuppet.runtime.bench.latency import _add_arguments
from facepuppet.runtime.bench.senders import SENDERS, decode_cost
from facepuppet.runtime.inputs.kinds import make_adapter


@pytest.mark.parametrize("kind", sorted(SENDERS))
def test_the_bench_sender_frames_decode_into_frames(kind):
    frames = SENDERS[kind]("127.0.0.1", 9)
    try:
        adapter = make_adapter(kind)
        got = [adapter.handle(d, 0.0) for k in range(5) for d in frames.datagrams(k / 60)]
    finally:
        frames.close()
    assert sum(f is not None for f in got) == 5 and adapter.counters["internal_error"] == 0
    # (VMC: the preset "Neutral" drives no ARKit channel and is counted as unmapped_name)
    assert all(c == 0 for k, c in adapter.counters.items() if k not in ("datagrams", "frames", "unmapped_name"))


@pytest.mark.parametrize("kind", sorted(SENDERS))
def test_decode_cost_times_every_datagram(kind):
    result = decode_cost(kind, n=400)
    per_frame = result["datagrams_per_frame"]
    assert result["datagrams"] == 400 and result["frames"] == 400 // per_frame and result["internal_error"] == 0
    assert 0 < result["p50_us"] <= result["p99_us"] <= result["max_us"]


def test_input_option_lists_the_kinds():
    parser = argparse.ArgumentParser()
    _add_arguments(parser)
    for kind in ("openseeface", "ifacialmocap", "vtubestudio"):
        assert parser.parse_args(["-c", "x.npz", "--input", kind]).input == kind
    assert parser.parse_args(["-c", "x.npz"]).input == "vmc"
