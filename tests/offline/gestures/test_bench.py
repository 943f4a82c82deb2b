"""Blink statistics of the gestures bench on constructed signals (what each definition counts)."""

import numpy as np

from facepuppet.offline.gestures.bench import (
    _block_bootstrap,
    blink_onsets,
    blink_onsets_hysteresis,
    short_blink_onsets,
)
from facepuppet.offline.gestures.database import Take


def lid(events, n=300):
    """An eyeBlink track: 0 with closures (start, frames, level) and optional chatter."""
    x = np.zeros(n)
    for start, frames, level in events:
        x[start:start + frames] = level
    return x


def test_crossings_hysteresis_and_short_closures_count_different_things():
    x = lid([(10, 4, 1.0), (100, 60, 1.0)])          # a blink and a held closure
    x[120:123] = 0.45                                 # the held closure dips just under 0.5: chatter
    np.testing.assert_array_equal(blink_onsets(x), [10, 100, 123])
    np.testing.assert_array_equal(blink_onsets_hysteresis(x), [10, 100])   # the dip is not a new blink
    np.testing.assert_array_equal(short_blink_onsets(x), [10])     # closures of <= 10 frames (20, 37 are held)
    assert len(blink_onsets_hysteresis(np.r_[np.ones(5), np.zeros(5)])) == 0  # starts closed: not a blink


def test_block_bootstrap_resamples_the_events_of_the_takes():
    blink = lid([(s, 4, 1.0) for s in range(30, 1200, 120)], n=1200)   # 10 blinks in 40 s: 15 per minute
    rng = np.random.default_rng(0)
    cols = {"eyeBlinkLeft": blink, "browInnerUp": rng.normal(0, 0.1, 1200)}
    take = Take("t", rng.normal(0, 1, 1200), cols, ("eyes",))
    boot = _block_bootstrap([take], list(cols), "eyeBlinkLeft", 30.0, np.random.default_rng(1))
    assert abs(np.mean(boot["blink_per_min"]) - 15.0) < 1.0
    lo, hi = np.percentile(boot["blink_per_min"], [2.5, 97.5])
    assert lo < 15.0 < hi and hi - lo > 1.0 and boot["energy_intensity_corr"].shape == (1000,)
