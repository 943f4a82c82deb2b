"""The measures of what limits the voice's r: the sound-to-curve lag, causal output smoothing chosen on training
folds, the linear ceiling, and the per-hop features matching the per-frame ones the fit uses."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec, features_of

from facepuppet.offline.voice.fit import contiguous_folds
from facepuppet.offline.voice.limits import (
    curve_lag,
    frame_hops,
    hop_features,
    linear_ceiling,
    one_pole,
    smoothing_choice,
)
from helpers.noise_bursts import bursts as noise_bursts


def bursts(seconds: float = 20.0, seed: int = 0) -> np.ndarray:
    return noise_bursts(seconds, seed)


def test_hop_features_at_frame_hops_are_the_fits_frame_features():
    spec = FeatureSpec(n_mels=8, n_taps=3, step=2)
    x = bursts(3.0)
    frames = np.arange(90) / 30.0
    H = hop_features(x, spec)
    assert np.array_equal(H[frame_hops(90, 30.0, spec)], features_of(x, spec, frames))


def test_curve_lag_finds_a_curve_that_trails_the_sound_by_100_ms():
    spec = FeatureSpec(n_mels=4, n_taps=1, step=1)
    x = bursts()
    H = hop_features(x, spec)
    n = int(20.0 * 30)
    level = H[:, -1]
    late = frame_hops(n, 30.0, spec, offset_s=-0.1)  # the curve at t is the level of t - 100 ms
    curve = np.clip((level[late] + 60.0) / 60.0, 0.0, 1.0)
    lag_s, r = curve_lag(level, curve, frame_hops(n, 30.0, spec), np.arange(n), spec.hop_s, max_lag_s=0.2)
    assert abs(lag_s - 0.1) <= spec.hop_s + 1e-9
    assert r > 0.99


def test_one_pole_is_causal_and_passes_a_constant():
    x = np.zeros((50, 2))
    x[30:] = 1.0
    y = one_pole(x, 0.8)
    assert np.all(y[:30] == 0.0)  # nothing before the step moves
    assert np.allclose(one_pole(np.full((40, 2), 0.3), 0.9), 0.3)
    assert np.array_equal(one_pole(x, 0.0), x)


def test_smoothing_is_chosen_on_training_folds_for_noisy_predictions_and_not_for_clean_ones():
    spec = FeatureSpec(n_mels=6, n_taps=2, step=2)
    rng = np.random.default_rng(3)
    x = bursts(24.0, seed=4)
    H = hop_features(x, spec)
    n = int(24.0 * 30)
    fh = frame_hops(n, 30.0, spec)
    smooth = one_pole(np.clip((H[:, -1:] + 60.0) / 60.0, 0, 1), 0.9)  # a slow mouth following the level
    Y = smooth[fh]
    folds = contiguous_folds(n, 5)
    noisy_H = H.copy()
    noisy_H[:, -1] += 15.0 * rng.standard_normal(len(H))  # the level the model reads is noisy per hop
    got = smoothing_choice(noisy_H, Y, fh, folds, train=(0, 1, 2), test=(3, 4), hop_s=spec.hop_s, alpha=10.0)
    assert got["tau_s"] > 0.0
    assert got["r_smoothed"][0] > got["r_raw"][0]
    clean = smoothing_choice(np.hstack([H, smooth]), Y, fh, folds, train=(0, 1, 2), test=(3, 4),
                             hop_s=spec.hop_s, alpha=1e-6)
    assert clean["tau_s"] == 0.0  # a model already right is not smoothed


def test_the_linear_ceiling_of_a_linear_target_is_one():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((300, 5))
    Y = X @ rng.standard_normal((5, 2))
    r = linear_ceiling(X, Y, [np.arange(100, 200), np.arange(200, 300)])
    assert np.all(r > 0.999)
