"""ReplaySource: pauses longer than the gap limit are cut, counted and reported."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv
from facepuppet.runtime.recording.replay_source import ReplaySource


def frames_at(times):
    return [Frame(t=t, source="vmc", channels=("jawOpen",), weights=np.array([i / 10], np.float32))
            for i, t in enumerate(times)]


def test_a_frame_at_1e300_after_0_is_brought_to_the_gap_limit():
    source = ReplaySource(frames_at([0.0, 1 / 60, 1e300]))
    assert source.duration == pytest.approx(10.0 + 1 / 60)
    assert source.gaps == [(2, pytest.approx(1e300))]
    assert "cut 1 pauses longer than the gap limit (first at frame 2" in source.describe_gaps()
    delivered = []
    t = 0.0
    while not source.done(t):
        frame, _ = source.latest(t)
        if frame is not None:
            delivered.append(frame.weights[0])
        t += 0.5
    assert delivered == pytest.approx([0.0, 0.1, 0.2])
    assert t == 11.0  # done at the first check after the last frame (delivered at t = 10.5)


def test_gaps_within_the_limit_and_inf_keep_their_length():
    times = [0.0, 4.0, 9.5, 30.0]
    assert ReplaySource(frames_at(times), max_gap=math.inf).duration == 30.0
    kept = ReplaySource(frames_at(times), max_gap=10.0)
    assert kept.duration == pytest.approx(4.0 + 5.5 + 10.0) and kept.gaps == [(3, pytest.approx(20.5))]
    assert ReplaySource(frames_at(times[:3])).gaps == [] and ReplaySource(frames_at(times[:3])).describe_gaps() == ""


def test_a_live_link_face_timecode_jumping_to_23_00_is_cut(tmp_path):
    rows = ["10:00:00:00.000", "10:00:00:01.000", "23:00:00:00.000", "23:00:00:01.000"]
    path = tmp_path / "jump.csv"
    path.write_text("Timecode,BlendShapeCount,JawOpen\n" + "".join(f"{tc},61,0.5\n" for tc in rows),
                    encoding="utf-8")
    source = ReplaySource(read_llf_csv(path), max_gap=10.0)
    assert source.duration == pytest.approx(10.0 + 2 / 60)
    assert source.gaps == [(2, pytest.approx(13 * 3600 - 1 / 60))]


def test_the_limit_must_be_positive():
    with pytest.raises(ValueError, match="max_gap: expected a positive number"):
        ReplaySource(frames_at([0.0]), max_gap=0.0)
