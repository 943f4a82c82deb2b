"""The look-ahead trade-off curve: a mouth that moves before its sound is read better with look-ahead, and the
curve carries both evaluations for every look-ahead asked."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec

from facepuppet.offline.voice.limits import frame_hops, hop_features
from facepuppet.offline.voice.lookahead import curve_lines, lookahead_curve
from helpers.noise_bursts import bursts as noise_bursts


def bursts(seconds: float = 24.0, seed: int = 3) -> np.ndarray:
    return noise_bursts(seconds, seed)


def test_a_mouth_that_leads_its_sound_by_100_ms_is_read_better_with_100_ms_of_look_ahead():
    spec = FeatureSpec(n_mels=4, n_taps=2, step=2)
    x = bursts()
    n = int(24.0 * 30) - 10
    level = hop_features(x, spec)[:, -1]
    ahead = np.minimum(frame_hops(n, 30.0, spec, offset_s=0.1), len(level) - 1)  # the mouth at t: the sound at t+100
    Y = np.clip((level[ahead] + 60.0) / 60.0, 0.0, 1.0)[:, None]
    curve = lookahead_curve(x, spec, Y, ["jawOpen"], 30.0, lookaheads_ms=(0.0, 100.0))
    assert curve["lookahead_ms"] == [0.0, 100.0] and curve["models"] == ["level", "ridge"]
    for where in ("cross_validated", "held_out_take"):
        r0, r100 = (curve[where][k]["ridge"]["jawOpen"] for k in ("0", "100"))
        assert r100 > 0.95 > r0 + 0.1, (where, r0, r100)
        assert set(curve[where]["100"]) == {"level", "ridge"}
    lines = curve_lines(curve, focus=("jawOpen",))
    assert len(lines) == 3 and "100 ms" in lines[2]
