"""Small voice tables built from arrays (no fit): ridge-, kernel-PLS- and blend-like tables of the real format."""

from __future__ import annotations

import wave

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec
from facepuppet.runtime.voice.table import VoiceTable

OUTPUTS = ("jawOpen", "mouthFunnel")


def small_table(model: str = "ridge", seed: int = 0, outputs=OUTPUTS, level_ref_s: float = 0.0) -> VoiceTable:
    """A table whose jawOpen grows with the level and the low bands, mouthFunnel with the high bands."""
    spec = FeatureSpec(n_mels=8, n_taps=3, step=2, level_ref_s=level_ref_s)
    nf, m = spec.n_features, len(outputs)
    rng = np.random.default_rng(seed)
    mean = np.full(nf, -60.0)
    scale = np.full(nf, 20.0)
    coef = np.zeros((nf, m))
    coef[:4, 0] = 0.05  # low bands of the newest frame open the jaw
    coef[-1, 0] = 0.1  # and the level
    coef[4:8, min(1, m - 1)] = 0.08
    common = dict(outputs=outputs, spec=spec, model=model, feature_mean=mean, feature_scale=scale,
                  output_mean=np.full(m, 0.1), gate_db=-60.0)
    if model == "blend":  # 4 random trees of depth 2 per output, their leaves small
        n_trees = 4 * m
        return VoiceTable(coef=coef, tree_feature=rng.integers(0, nf, (n_trees, 3)),
                          tree_threshold=rng.standard_normal((n_trees, 3)),
                          tree_value=0.05 * rng.standard_normal((n_trees, 4)), **common)
    if model != "kpls":
        return VoiceTable(coef=coef, **common)
    n = 40
    X = rng.standard_normal((n, nf))
    B = 0.05 * rng.standard_normal((n, m))
    return VoiceTable(train_inputs=X, dual_coef=B, kernel_col_mean=np.full(n, 0.1), kernel_grand_mean=0.1,
                      gamma=1.0 / nf, **common)


def write_wav(path, samples: np.ndarray, rate: int = 16000) -> None:
    """Float samples in [-1, 1] as a 16-bit mono WAV."""
    with wave.open(str(path), "wb") as f:
        f.setnchannels(1)
        f.setsampwidth(2)
        f.setframerate(rate)
        f.writeframes((np.clip(samples, -1, 1) * 32767).astype("<i2").tobytes())


def vowel_buzz(seconds: float, rate: int = 16000, on_off_hz: float = 1.5, amplitude: float = 0.4) -> np.ndarray:
    """A buzzy 140 Hz source through a 700 Hz resonance, switched on and off: speech-like level and spectrum."""
    t = np.arange(int(seconds * rate)) / rate
    buzz = np.sign(np.sin(2 * np.pi * 140 * t)) * np.sin(2 * np.pi * 700 * t)
    return amplitude * buzz * (np.sin(2 * np.pi * on_off_hz * t) > 0)
