"""Noise bursts of random length and loudness with silences between: a level that jumps, for the voice's fits."""

from __future__ import annotations

import numpy as np

RATE = 16000


def bursts(seconds: float, seed: int) -> np.ndarray:
    """``seconds`` of noise bursts (0.08-0.4 s, 60 % of them sounding, amplitude 0.02-0.4) at :data:`RATE`."""
    rng = np.random.default_rng(seed)
    x = np.zeros(int(seconds * RATE))
    i = 0
    while i < len(x):
        n = int(rng.uniform(0.08, 0.4) * RATE)
        if rng.random() < 0.6:
            x[i:i + n] = rng.uniform(0.02, 0.4) * rng.standard_normal(min(n, len(x) - i))
        i += n
    return x
