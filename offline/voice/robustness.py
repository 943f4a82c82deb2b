"""Does a voice table read another microphone as it read its training speech? Held-out r under the changes a
different microphone or room brings.

A table is fitted on one recording; a user speaks into another microphone, at another gain, with another
frequency response. This measure fits each model on folds 1-3 of the take as recorded and scores it on folds
4-5 changed: scaled by a gain (dB), or tilted (a first-order shelf that lifts or cuts the highs, as a brighter
or duller microphone does). The features are computed from the changed samples by the runtime's own extractor,
from the start of the file, so a running level follows the change as it would in a run.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import lfilter

from facepuppet.runtime.voice.features import FeatureSpec, features_of

from facepuppet.offline.voice.fit import choose_setting, contiguous_folds, fit_model, fold_r

GAINS_DB = (-20.0, -10.0, 0.0, 6.0)
TILTS_DB = (-6.0, 6.0)  # shelf gain above ~2 kHz
MODELS = ("ridge", "blend")


def tilt(samples: np.ndarray, rate: float, shelf_db: float, corner_hz: float = 2000.0) -> np.ndarray:
    """A first-order high shelf: the highs (over ``corner_hz``) ``shelf_db`` louder, the lows unchanged."""
    g = 10.0 ** (shelf_db / 20.0)
    k = np.tan(np.pi * corner_hz / rate)
    # bilinear transform of H(s) = (g s + w) / (s + w), w the corner
    b = np.array([g + k, k - g]) / (1.0 + k)
    a = np.array([1.0, (k - 1.0) / (1.0 + k)])
    return np.clip(lfilter(b, a, samples), -1.0, 1.0)


def changed_r(samples: np.ndarray, spec: FeatureSpec, Y: np.ndarray, channels: Sequence[str], fps: float,
              models: Sequence[str] = MODELS, gains_db: Sequence[float] = GAINS_DB,
              tilts_db: Sequence[float] = TILTS_DB, k: int = 5) -> dict:
    """Per change, per model, per channel r on folds 4-5 of a model fitted on folds 1-3 as recorded.

    Returns {"gain_db": {g: {model: {channel: r}}}, "tilt_db": {t: {...}}} with the numbers as strings (JSON keys).
    """
    times = np.arange(len(Y)) / fps
    folds = contiguous_folds(len(Y), k)
    train = np.concatenate(folds[:3])
    test = np.concatenate(folds[3:])
    scored = [np.arange(len(folds[3])), np.arange(len(folds[3]), len(test))]
    X = features_of(samples, spec, times)
    fitted = {m: fit_model(m, X[train], Y[train], choose_setting(m, X[train], Y[train])) for m in models}

    def score(x: np.ndarray) -> dict:
        Xc = features_of(x, spec, times)[test]
        return {m: {c: float(r) for c, r in zip(channels, fold_r(f(Xc), Y[test], scored))} for m, f in fitted.items()}

    return {"gain_db": {f"{g:g}": score(np.clip(samples * 10.0 ** (g / 20.0), -1.0, 1.0)) for g in gains_db},
            "tilt_db": {f"{t:g}": score(tilt(samples, spec.sample_rate, t)) for t in tilts_db}}


def changed_lines(result: dict, focus: Sequence[str] = ("jawOpen", "mouthFunnel")) -> list[str]:
    """The measure in words: per change and model, the focus channels' r and the mean over all channels."""
    lines = ["another microphone (fitted on folds 1-3 as recorded, scored on folds 4-5 changed):"]
    for kind, label in (("gain_db", "gain"), ("tilt_db", "highs")):
        for key, per in result[kind].items():
            parts = []
            for name, r in per.items():
                parts.append(f"{name} " + " ".join(f"{c} {r[c]:.3f}" for c in focus if c in r)
                             + f" mean {np.nanmean(list(r.values())):.3f}")
            lines.append(f"  {label} {float(key):+g} dB: " + "; ".join(parts))
    return lines
