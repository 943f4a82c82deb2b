"""The learning curve of the voice models (trained on growing starts of a take, scored on its end, which no
training part contains) and the measure of another microphone (gain, tilt)."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec

from facepuppet.offline.voice.learning import learning_curve, learning_lines
from facepuppet.offline.voice.robustness import changed_lines, changed_r, tilt


def test_more_training_rows_lift_a_model_short_of_data_and_the_curve_says_so():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((400, 60))
    w = rng.standard_normal(60)
    Y = np.c_[X @ w + 2.0 * rng.standard_normal(400)]
    curve = learning_curve(X, Y, ["jawOpen"], fps=40.0, models=("ridge",))
    assert curve["train_s"] == [2.0, 4.0, 6.0, 8.0] and curve["test_s"] == 2.0
    r = curve["r"]["ridge"]["jawOpen"]
    assert r[-1] > r[0] + 0.05  # 80 rows of 60 features pin little down; 320 rows pin more
    assert curve["rise_last_doubling"]["ridge"]["jawOpen"] == r[-1] - r[1]
    assert any("jawOpen" in line for line in learning_lines(curve))


def test_the_scored_end_of_the_take_is_never_trained_on():
    rng = np.random.default_rng(1)
    X = rng.standard_normal((500, 3))
    y = X[:, 0].copy()
    y[400:] = -y[400:]  # the last two of ten blocks follow the opposite rule
    curve = learning_curve(X, np.c_[y], ["jawOpen"], fps=50.0, models=("ridge",))
    # trained on the start alone, every model reads the end backwards; any of the end in training would not
    assert max(curve["r"]["ridge"]["jawOpen"]) < -0.95


def test_the_tilt_of_another_microphone_keeps_the_lows_and_scales_the_highs():
    rate = 16000.0
    t = np.arange(int(rate)) / rate
    for shelf in (-6.0, 6.0):
        for hz, expect_db in ((100.0, 0.0), (7000.0, shelf)):
            x = 0.1 * np.sin(2 * np.pi * hz * t)
            y = tilt(x, rate, shelf)
            got = 20 * np.log10(np.std(y[4000:]) / np.std(x[4000:]))
            assert abs(got - expect_db) < 0.6, (shelf, hz, got)


def test_another_microphone_is_scored_per_change_model_and_channel():
    rate = 16000
    t = np.arange(6 * rate) / rate
    env = 0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t)
    x = 0.3 * env * np.sign(np.sin(2 * np.pi * 130 * t)) * np.sin(2 * np.pi * 600 * t)
    frames = np.arange(6 * 30) / 30
    Y = np.c_[np.interp(frames, t, env)]
    out = changed_r(x, FeatureSpec(level_ref_s=3.0, n_mels=8, n_taps=2), Y, ["jawOpen"], 30.0, models=("ridge",))
    assert sorted(out) == ["gain_db", "tilt_db"] and list(out["gain_db"]) == ["-20", "-10", "0", "6"]
    # the loudness envelope is the jaw here: read relative to the running level it survives a gain change
    assert out["gain_db"]["-10"]["ridge"]["jawOpen"] > 0.8
    assert any("gain -10 dB" in line for line in changed_lines(out))
