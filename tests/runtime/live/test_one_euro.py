"""One Euro filter: the vectorised filter against a slow scalar reference, and its known behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.live.one_euro import OneEuroFilter


class ScalarOneEuro:
    """Casiez et al. 2012, written out one channel at a time (the obvious reference)."""

    def __init__(self, min_cutoff, beta, d_cutoff):
        self.min_cutoff, self.beta, self.d_cutoff = min_cutoff, beta, d_cutoff
        self.x_prev = None
        self.dx_prev = 0.0

    @staticmethod
    def alpha(cutoff, dt):
        tau = 1.0 / (2 * math.pi * cutoff)
        return 1.0 / (1.0 + tau / dt)

    def __call__(self, x, dt):
        if math.isnan(x):
            return math.nan
        if self.x_prev is None:
            self.x_prev = x
            return x
        dx = (x - self.x_prev) / dt
        a_d = self.alpha(self.d_cutoff, dt)
        dx_hat = a_d * dx + (1 - a_d) * self.dx_prev
        cutoff = self.min_cutoff + self.beta * abs(dx_hat)
        a = self.alpha(cutoff, dt)
        x_hat = a * x + (1 - a) * self.x_prev
        self.x_prev, self.dx_prev = x_hat, dx_hat
        return x_hat


def test_vectorised_filter_matches_the_scalar_reference_with_per_channel_settings_and_gaps():
    rng = np.random.default_rng(3)
    n, steps = 7, 400
    min_cutoff = rng.uniform(0.5, 5.0, n)
    beta = rng.uniform(0.0, 2.0, n)
    d_cutoff = rng.uniform(0.5, 2.0, n)
    t = np.cumsum(rng.uniform(0.005, 0.03, steps))  # irregular sampling
    x = np.sin(t[:, None] * rng.uniform(1, 10, n)) + rng.normal(0, 0.05, (steps, n))
    x[rng.random((steps, n)) < 0.1] = np.nan  # channels missing now and then
    x[:5, 2] = np.nan  # a channel that starts late
    fast = OneEuroFilter(n, min_cutoff, beta, d_cutoff)
    slow = [ScalarOneEuro(min_cutoff[i], beta[i], d_cutoff[i]) for i in range(n)]
    # the reference keeps per-channel time of its last sample, like the vectorised state (dt is per call)
    for k in range(steps):
        dt = t[k] - t[k - 1] if k else 1 / 60
        got = fast.filter(x[k], dt).copy()
        want = np.array([slow[i](x[k, i], dt) for i in range(n)])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, equal_nan=True)


def test_constant_input_passes_through_exactly():
    f = OneEuroFilter(3, min_cutoff=1.0, beta=0.5)
    for _ in range(100):
        out = f.filter(np.array([0.25, 0.0, 1.0]), 1 / 60)
    np.testing.assert_array_equal(out, [0.25, 0.0, 1.0])


def test_jitter_on_a_still_signal_is_reduced():
    rng = np.random.default_rng(0)
    noisy = 0.5 + rng.normal(0, 0.05, 600)
    f = OneEuroFilter(1, min_cutoff=1.0, beta=0.5)
    out = np.array([f.filter(noisy[k:k + 1], 1 / 60)[0] for k in range(600)])
    assert out[60:].std() < 0.3 * noisy[60:].std()
    assert abs(out[60:].mean() - 0.5) < 0.02


def test_lag_is_small_for_fast_motion_thanks_to_beta():
    # a ramp at 10 units/s: the steady lag is v * tau(f_c); beta raises f_c with the speed
    dt, v = 1 / 120, 10.0
    ramp = v * dt * np.arange(240)

    def lag(beta):
        f = OneEuroFilter(1, min_cutoff=1.0, beta=beta)
        out = [f.filter(ramp[k:k + 1], dt)[0] for k in range(240)]
        return ramp[-1] - out[-1]

    lag_fast, lag_plain = lag(1.0), lag(0.0)
    assert lag_plain == pytest.approx(v / (2 * math.pi * 1.0), rel=0.1)  # tau = 1 / (2 pi f_cmin)
    assert lag_fast < 0.2 and lag_fast < lag_plain / 5


def test_missing_sample_leaves_the_state_and_reset_forgets_it():
    f = OneEuroFilter(2, min_cutoff=1.0)
    f.filter(np.array([0.0, 0.0]), 0.01)
    out = f.filter(np.array([np.nan, 1.0]), 0.01)
    assert math.isnan(out[0]) and 0 < out[1] < 1
    assert f.x_hat[0] == 0.0
    f.reset()
    np.testing.assert_array_equal(f.filter(np.array([0.7, 0.3]), 0.01), [0.7, 0.3])


def test_bad_settings_and_shapes_are_refused():
    with pytest.raises(ValueError, match="min_cutoff"):
        OneEuroFilter(2, min_cutoff=0.0)
    with pytest.raises(ValueError, match="beta"):
        OneEuroFilter(2, beta=-1.0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        OneEuroFilter(2).filter(np.zeros(3), 0.01)
