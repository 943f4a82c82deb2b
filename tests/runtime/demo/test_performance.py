"""The synthetic demo performance: length, determinism, plausibility of its curves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.demo.performance import DEMO_CHANNELS, demo_curves, demo_frames
from facepuppet.runtime.mapping.channels import ARKIT_NAMES


@pytest.fixture(scope="module")
def frames():
    return demo_frames()


def _column(frames, name):
    k = DEMO_CHANNELS.index(name)
    return np.array([f.weights[k] for f in frames])


def test_timing_and_identity(frames):
    assert len(frames) == 720
    t = np.array([f.t for f in frames])
    assert t[0] == 0.0 and t[-1] >= 10.0
    np.testing.assert_allclose(np.diff(t), 1 / 60.0, rtol=1e-9)
    assert [f.number for f in frames] == list(range(len(frames)))
    assert {f.source for f in frames} == {"demo"}
    assert all(f.channels == DEMO_CHANNELS for f in frames)
    assert set(DEMO_CHANNELS) <= set(ARKIT_NAMES)
    assert all(f.is_finite() for f in frames)


def test_weights_in_unit_range(frames):
    w = np.stack([f.weights for f in frames])
    assert w.min() >= 0.0 and w.max() <= 1.0
    assert np.all(w.max(axis=0) > 0.05)  # every channel is used


def test_same_seed_same_frames_other_seed_differs(frames):
    again = demo_frames()
    for a, b in zip(frames, again):
        assert a.t == b.t and a.audio_level == b.audio_level
        np.testing.assert_array_equal(a.weights, b.weights)
        np.testing.assert_array_equal(a.head_rotation, b.head_rotation)
        np.testing.assert_array_equal(a.head_translation, b.head_translation)
    other = demo_frames(seed=1)
    assert not np.array_equal(np.stack([f.weights for f in frames]), np.stack([f.weights for f in other]))


def test_jaw_follows_audio(frames):
    jaw = _column(frames, "jawOpen")
    level = np.array([f.audio_level for f in frames])
    assert np.corrcoef(jaw, level)[0, 1] > 0.5
    assert level.min() == pytest.approx(-60.0) and -30.0 < level.max() <= -12.0
    silent = level <= -59.9
    assert 0.1 < silent.mean() < 0.7  # phrases with pauses between them
    assert jaw[silent].max() < 0.05


def test_blinks_and_a_wink(frames):
    left, right = _column(frames, "eyeBlinkLeft"), _column(frames, "eyeBlinkRight")
    closes = lambda w: int(np.sum(np.diff((w > 0.8).astype(int)) == 1))  # noqa: E731
    assert closes(right) >= 2
    assert closes(left) > closes(right)  # one closing is a wink of the left eye
    closed = np.flatnonzero(right > 0.8)
    runs = np.split(closed, np.flatnonzero(np.diff(closed) > 1) + 1)
    assert all(len(run) / 60.0 < 0.2 for run in runs)  # a blink is brief


def test_head_moves(frames):
    q = np.stack([f.head_rotation for f in frames])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    assert np.ptp(q, axis=0)[:3].max() > 0.05
    tr = np.stack([f.head_translation for f in frames])
    assert 0.0 < np.abs(tr).max() < 5.0  # cm


def test_duration_and_rate():
    c = demo_curves(duration=2.5, rate=30.0, seed=3)
    assert len(c.t) == 75 and c.weights.shape == (75, len(DEMO_CHANNELS))
    with pytest.raises(ValueError, match="duration"):
        demo_frames(duration=0.0)
    with pytest.raises(ValueError, match="rate"):
        demo_frames(rate=math.nan)
