"""The learning curve of the voice models: trained on growing starts of a take, scored on its end, which no
training part contains."""

from __future__ import annotations

import numpy as np

from facepuppet.offline.voice.learning import learning_curve, learning_lines


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
