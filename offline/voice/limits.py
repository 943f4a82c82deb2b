"""What limits the voice's held-out r on a take: measures that say where the missing accuracy is, not models.

When a table misses its goals there are three usual suspects, and each has a measure here:

* the **target's timing**: a constant offset between the audio and the curves caps any causal reader.
  :func:`curve_lag` cross-correlates the window level with a curve over lags (in hops) and gives the lag of
  the peak; a clear non-zero lag, estimated on training folds, would be a delay to record in the table;
* **noise in the per-hop predictions**: the curves are smooth at 30 fps while a prediction is made every hop
  from one window. :func:`smoothing_choice` fits ridge on training folds, runs it on every hop as the run
  does, passes each channel through a causal one-pole (:func:`one_pole`), and picks the time constant on
  the training folds (0 allowed), then scores it on the held-out folds with and without;
* the **features themselves**: :func:`linear_ceiling` fits ridge on the held-out rows *themselves*; the
  r it reaches is the most any linear reader of these features could give there, so a goal above it needs
  other features or another kind of model, not other settings.

Per-hop features (:func:`hop_features`) are the streaming extractor's vector after every hop, row 0 being
the vector before any hop; :func:`frame_hops` gives the row a frame time reads, the same one
:func:`~facepuppet.runtime.voice.features.features_of` computes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec, VoiceFeatures

from facepuppet.offline.voice.fit import contiguous_folds, fit_model, fold_r, pearson

SMOOTHING_TAUS_S = (0.0, 0.01, 0.02, 0.04, 0.08, 0.16)


def hop_features(samples: np.ndarray, spec: FeatureSpec) -> np.ndarray:
    """The feature vector before any hop and after each hop of ``samples``, shape (1 + hops, n_features)."""
    ex = VoiceFeatures(spec)
    hop_n = ex.hop_n
    n_hops = len(samples) // hop_n
    out = np.empty((n_hops + 1, spec.n_features))
    out[0] = ex.vector()
    for k in range(n_hops):
        ex.push(samples[k * hop_n:(k + 1) * hop_n])
        out[k + 1] = ex.vector()
    return out


def frame_hops(n_frames: int, fps: float, spec: FeatureSpec, offset_s: float = 0.0) -> np.ndarray:
    """Row of :func:`hop_features` read at each frame time ``i / fps + offset_s`` (hops completed by then)."""
    hop_n = max(1, int(round(spec.hop_s * spec.sample_rate)))
    ends = np.round((np.arange(n_frames) / fps + offset_s) * spec.sample_rate).astype(np.int64)
    return np.maximum(ends, 0) // hop_n


def one_pole(P: np.ndarray, a: float) -> np.ndarray:
    """Causal one-pole smoothing along axis 0: ``s_k = a s_(k-1) + (1 - a) p_k``, starting at ``p_0``."""
    out = np.empty_like(P, dtype=np.float64)
    s = np.array(P[0], np.float64)
    b = 1.0 - a
    for k in range(len(P)):
        s = a * s + b * P[k]
        out[k] = s
    return out


def curve_lag(level: np.ndarray, curve: np.ndarray, hops: np.ndarray, rows: np.ndarray, hop_s: float,
              max_lag_s: float = 0.2) -> tuple[float, float]:
    """The lag (s) at which the level best explains ``curve`` on ``rows``, and that r.

    level : (n_hops,) dB per hop row; curve : (n_frames,); hops : (n_frames,) rows of frames (frame_hops)
    A positive lag: the curve at t follows the level of t - lag (the mouth trails the sound).
    """
    k = int(round(max_lag_s / hop_s))
    best = (0.0, -math.inf)
    for lag in range(-k, k + 1):
        idx = np.clip(hops[rows] - lag, 0, len(level) - 1)
        r = pearson(level[idx], curve[rows])
        if math.isfinite(r) and r > best[1]:
            best = (lag * hop_s, r)
    return best


def _hop_predictions(H: np.ndarray, Y: np.ndarray, hops: np.ndarray, train_rows: np.ndarray,
                     alpha: float) -> np.ndarray:
    """Ridge fitted on the training frames, run on every hop row and clamped to [0, 1] as the run does."""
    model = fit_model("ridge", H[hops[train_rows]], Y[train_rows], alpha)
    return np.clip(model(H), 0.0, 1.0)


def smoothing_choice(H: np.ndarray, Y: np.ndarray, hops: np.ndarray, folds: Sequence[np.ndarray],
                     train: Sequence[int], test: Sequence[int], hop_s: float, alpha: float,
                     taus: Sequence[float] = SMOOTHING_TAUS_S) -> dict:
    """The one-pole time constant chosen on the training folds (leave one out among them), and the held-out r.

    Returns {"tau_s", "inner_r": {tau: mean r}, "r_raw": (m,), "r_smoothed": (m,)} (r per channel on ``test``).
    """
    inner = {}
    preds = []
    for k in train:
        rows = np.concatenate([folds[j] for j in train if j != k])
        preds.append((k, _hop_predictions(H, Y, hops, rows, alpha)))
    for tau in taus:
        a = math.exp(-hop_s / tau) if tau > 0 else 0.0
        r = [fold_r(one_pole(P, a)[hops], Y, [folds[k]]) for k, P in preds]
        inner[float(tau)] = float(np.nanmean(r))
    tau = max(inner, key=inner.get)
    P = _hop_predictions(H, Y, hops, np.concatenate([folds[j] for j in train]), alpha)
    scored = [folds[j] for j in test]
    a = math.exp(-hop_s / tau) if tau > 0 else 0.0
    return {"tau_s": tau, "inner_r": inner, "r_raw": fold_r(P[hops], Y, scored),
            "r_smoothed": fold_r(one_pole(P, a)[hops], Y, scored)}


def linear_ceiling(X: np.ndarray, Y: np.ndarray, folds: Sequence[np.ndarray], alpha: float = 10.0) -> np.ndarray:
    """Per channel, r of ridge fitted on all of ``folds`` and scored on them (the mean over the folds of r on
    each, as the held-out figures are): the most a linear reader of these features gives there."""
    rows = np.concatenate(list(folds))
    P = np.zeros_like(Y, dtype=np.float64)
    P[rows] = fit_model("ridge", X[rows], Y[rows], alpha)(X[rows])
    return fold_r(P, Y, list(folds))


def limits(samples: np.ndarray, spec: FeatureSpec, Y: np.ndarray, channels: Sequence[str], fps: float,
           alpha: float, k: int = 5, train: Sequence[int] = (0, 1, 2), test: Sequence[int] = (3, 4)) -> dict:
    """The three measures on one take (curves Y (n, m) at ``fps``), settings from ``train``, scores on ``test``."""
    H = hop_features(samples, spec)
    hops = np.minimum(frame_hops(len(Y), fps, spec), len(H) - 1)
    folds = contiguous_folds(len(Y), k)
    train_rows = np.concatenate([folds[j] for j in train])
    names = list(channels)
    jaw = names.index("jawOpen") if "jawOpen" in names else 0
    lag_s, lag_r = curve_lag(H[:, -1], Y[:, jaw], hops, train_rows, spec.hop_s)
    per_fold = [curve_lag(H[:, -1], Y[:, jaw], hops, f, spec.hop_s)[0] for f in folds]
    sm = smoothing_choice(H, Y, hops, folds, train, test, spec.hop_s, alpha)
    ceiling = linear_ceiling(H[hops], Y, [folds[j] for j in test])
    return {
        "alignment": {"channel": names[jaw], "lag_ms_training_folds": lag_s * 1000.0, "r_at_lag": lag_r,
                      "lag_ms_per_fold": [v * 1000.0 for v in per_fold],
                      "note": "positive: the curve trails the sound; within about a hop of 0 is no offset"},
        "output_smoothing": {"tau_ms": sm["tau_s"] * 1000.0,
                             "inner_r": {f"{t * 1000:g}ms": v for t, v in sm["inner_r"].items()},
                             "r_raw": dict(zip(names, map(float, sm["r_raw"]))),
                             "r_smoothed": dict(zip(names, map(float, sm["r_smoothed"])))},
        "linear_ceiling_on_test_folds": dict(zip(names, map(float, ceiling))),
    }
