"""A take's own frame rate from its frame times: jitter, dropped frames, pauses and bursts do not move it."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.recording.take_rate import take_rate

from conftest import need_shared


def _times(rate, n, jitter_s=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return np.arange(n) / rate + 1234.5 + rng.uniform(-jitter_s, jitter_s, n)


@pytest.mark.parametrize("rate", [23.976, 25.0, 29.97, 30.0, 59.94, 60.0, 120.0])
def test_common_rates_with_a_timecode_jitter_come_out_exact(rate):
    # a millisecond of jitter, as a Live Link Face sub-frame stamp or a network arrival has
    assert take_rate(_times(rate, 300, jitter_s=1e-3)) == rate


def test_dropped_frames_a_long_pause_and_bursts_are_left_out():
    t = list(_times(30.0, 400, jitter_s=5e-4))
    del t[100:103]                                   # three frames dropped
    t = t[:200] + [x + 3600.0 for x in t[200:]]      # an hour's pause
    t = sorted(t + [t[50] + 1e-3, t[60] + 1e-3])     # two packets a millisecond after their frame
    assert take_rate(t) == 30.0


def test_an_uncommon_rate_is_kept_to_a_millisecond_hertz():
    assert take_rate(_times(37.5, 200)) == 37.5
    assert take_rate(_times(33.3333, 200)) == pytest.approx(33.333, abs=1e-3)


@pytest.mark.parametrize("times", [[], [0.0], [0.0, 0.1], [1.0, 1.0, 1.0], [0.0, 1e-6, 2e-6, 3e-6],
                                   [0.0, 5.0, 10.0, 15.0], [0.0, 1.0, float("nan"), 3.0]])
def test_no_steady_rate_says_none(times):
    assert take_rate(times) is None


def test_on_the_grid_each_jittered_frame_is_due_at_its_own_tick():
    rate, n = 30.0, 300
    t = _times(rate, n, jitter_s=1e-3)
    source = ReplaySource([Frame(t=x, source="t", channels=("a",), weights=np.zeros(1, np.float32)) for x in t],
                          grid_fps=rate)
    got = [source.latest(k / rate) for k in range(n)]
    assert all(frame is not None and stale == 0 for frame, stale in got)
    assert [frame.t for frame, _ in got] == list(t)


@pytest.mark.data
@pytest.mark.parametrize("name, rate", [("livelinkface_alex_rom_3.csv", 30.0), ("livelinkface_myslate_3.csv", 59.94)])
def test_the_kits_live_link_face_takes(name, rate):
    frames = read_llf_csv(need_shared("tracker", name))
    assert take_rate([f.t for f in frames]) == rate
