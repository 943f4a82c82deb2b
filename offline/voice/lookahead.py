"""The voice's look-ahead trade-off: held-out r against how far past each mouth frame the features hear.

A mouth shapes itself before the sound it makes (the lips round before an /u/, close before a /p/), and the
kit's curves were made from a window centred on each frame, so features that hear a little of the future
read the mouth better. Each millisecond of look-ahead is a millisecond of delay at run time, though, and the
issue's latency goal (one audio block plus one frame, <= 40 ms) is for the causal default. This module
measures the curve so the choice is a documented trade-off: for each look-ahead, the same two evaluations
``bench voice`` gives the default (contiguous k folds with settings chosen inside the training folds, and
settings chosen on folds 1-3 scored once on folds 4-5), for the level baseline and ridge (kernel PLS left
out: its cost per setting would multiply the bench's time by the number of look-aheads for a curve ridge
already draws).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from facepuppet.runtime.voice.features import FeatureSpec, features_of

from facepuppet.offline.voice.fit import cross_validate

LOOKAHEADS_MS = (0.0, 50.0, 100.0, 200.0, 260.0)
CURVE_MODELS = ("level", "ridge")


def lookahead_curve(samples: np.ndarray, spec: FeatureSpec, Y: np.ndarray, channels: Sequence[str], fps: float,
                    lookaheads_ms: Sequence[float] = LOOKAHEADS_MS, models: Sequence[str] = CURVE_MODELS,
                    k: int = 5, test_folds: Sequence[int] = (3, 4),
                    progress: Callable[[str], None] | None = None) -> dict:
    """Per look-ahead, per model, per channel held-out r under both evaluations.

    samples : (n_samples,) float at ``spec.sample_rate``; Y : (n_frames, m) curves at ``fps``
    Returns {"lookahead_ms": [...], "models": [...], "cross_validated": {ms: {model: {channel: r}}},
    "held_out_take": {ms: {model: {channel: r}}}} with ms as strings (JSON keys).
    """
    times = np.arange(len(Y)) / fps
    out: dict = {"lookahead_ms": [float(v) for v in lookaheads_ms], "models": list(models),
                 "cross_validated": {}, "held_out_take": {}}
    for ms in lookaheads_ms:
        X = features_of(samples, spec, times + ms / 1000.0)
        key = f"{ms:g}"
        for where, folds in (("cross_validated", None), ("held_out_take", test_folds)):
            cv = cross_validate(X, Y, k, models, test_folds=folds)
            out[where][key] = {name: {c: float(r) for c, r in zip(channels, v["r"])} for name, v in cv.items()}
        if progress is not None:
            progress(f"look-ahead {key} ms")
    return out


def curve_lines(curve: dict, focus: Sequence[str] = ("jawOpen", "mouthFunnel")) -> list[str]:
    """The curve in words: per look-ahead, ridge's r of the focus channels and its mean, both evaluations."""
    lines = ["look-ahead trade-off (ridge; r over 5 folds / on folds 4-5 with settings from folds 1-3):"]
    for key in curve["cross_validated"]:
        parts = []
        for c in focus:
            cv = curve["cross_validated"][key]["ridge"].get(c)
            held = curve["held_out_take"][key]["ridge"].get(c)
            if cv is not None:
                parts.append(f"{c} {cv:.3f} / {held:.3f}")
        means = [np.nanmean(list(curve[w][key]["ridge"].values())) for w in ("cross_validated", "held_out_take")]
        parts.append(f"mean {means[0]:.3f} / {means[1]:.3f}")
        lines.append(f"  {key:>5} ms: " + ", ".join(parts))
    return lines
