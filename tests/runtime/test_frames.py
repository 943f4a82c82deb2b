"""Frames are immutable and say explicitly what is missing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame


def test_frame_copies_and_freezes_its_arrays():
    weights = np.array([0.1, 0.2], np.float64)
    frame = Frame(t=1.5, source="test", channels=("jawOpen", "eyeBlinkLeft"), weights=weights)
    weights[0] = 9.0
    assert frame.weights.dtype == np.float32 and frame.weights[0] == pytest.approx(0.1)
    with pytest.raises(ValueError, match="read-only"):
        frame.weights[0] = 1.0
    with pytest.raises(AttributeError):
        frame.t = 2.0  # type: ignore[misc]
    assert math.isnan(frame.audio_level) and frame.head_rotation is None


def test_frame_checks_channel_count_and_shapes():
    with pytest.raises(ValueError, match=r"Frame.channels: 1 names for 2 weights"):
        Frame(t=0, channels=("a",), weights=[0.0, 1.0])
    with pytest.raises(ValueError, match=r"Frame.head_rotation"):
        Frame(t=0, head_rotation=[0, 0, 1])
    with pytest.raises(ValueError, match=r"Frame.markers"):
        Frame(t=0, markers=np.zeros(3))


def test_missing_is_allowed_but_infinite_is_not():
    ok = Frame(t=0, channels=("a", "b"), weights=[np.nan, 0.5], markers=[[np.nan, 0, 0]])
    assert ok.is_finite()
    assert not Frame(t=0, channels=("a",), weights=[np.inf]).is_finite()
    assert not Frame(t=0, head_rotation=[0, 0, np.nan, 1]).is_finite()
    assert not Frame(t=0, audio_level=-np.inf).is_finite()
