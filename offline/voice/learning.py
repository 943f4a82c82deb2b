"""Would more paired speech help? Held-out r against the seconds of speech a model was trained on.

The kit's voice goals are missed with 49 s of one speaker's paired speech, and the likeliest cure a user can
bring is more of it. This measure says whether that is so for each model, instead of assuming it: the take is
cut into ``k`` contiguous blocks, the last ``test_blocks`` are held out and never seen, and each model is fitted
on the first 2, 4, ... of the others (its settings chosen inside that training part, as everywhere in
``fit-voice``) and scored on the held-out end. A curve that still rises at the full training set says more
speech would lift that model; a flat one says it would not, and that other features or models are needed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.offline.voice.fit import choose_setting, contiguous_folds, fit_model, fold_r

CURVE_MODELS = ("ridge", "blend")


def learning_curve(X: np.ndarray, Y: np.ndarray, channels: Sequence[str], fps: float,
                   models: Sequence[str] = CURVE_MODELS, k: int = 10, test_blocks: int = 2) -> dict:
    """Per model, per channel, held-out r on the last ``test_blocks`` of ``k`` blocks, trained on the first 2, 4, ...

    Returns {"train_s": [...], "test_s": float, "r": {model: {channel: [r per training size]}},
    "rise_last_doubling": {model: {channel: r(full) - r(half)}}}.
    """
    blocks = contiguous_folds(len(X), k)
    test = [blocks[i] for i in range(k - test_blocks, k)]
    te = np.concatenate(test)
    scored, start = [], 0
    for b in test:  # r per held-out block, then their mean, as the folds of fit-voice are scored
        scored.append(np.arange(start, start + len(b)))
        start += len(b)
    sizes = list(range(2, k - test_blocks + 1, 2))
    if sizes[-1] != k - test_blocks:
        sizes.append(k - test_blocks)
    out: dict = {"train_s": [], "test_s": len(te) / fps, "r": {m: {c: [] for c in channels} for m in models}}
    for n_blocks in sizes:
        tr = np.concatenate(blocks[:n_blocks])
        out["train_s"].append(len(tr) / fps)
        for name in models:
            setting = choose_setting(name, X[tr], Y[tr])
            r = fold_r(fit_model(name, X[tr], Y[tr], setting)(X[te]), Y[te], scored)
            for c, v in zip(channels, r):
                out["r"][name][c].append(float(v))
    half = min(range(len(sizes)), key=lambda i: abs(sizes[i] - sizes[-1] / 2))
    out["rise_last_doubling"] = {m: {c: v[-1] - v[half] for c, v in per.items()} for m, per in out["r"].items()}
    return out


def learning_lines(curve: dict, focus: Sequence[str] = ("jawOpen", "mouthFunnel")) -> list[str]:
    """The curve in words, and what it says a user can do."""
    secs = " / ".join(f"{s:.0f}" for s in curve["train_s"])
    lines = [f"learning curve (r on the last {curve['test_s']:.0f} s, trained on the first {secs} s):"]
    for name, per in curve["r"].items():
        for c in focus:
            if c in per:
                rise = curve["rise_last_doubling"][name][c]
                lines.append(f"  {name:6s} {c:12s} " + " ".join(f"{v:.3f}" for v in per[c])
                             + f"  (last doubling {rise:+.3f}: "
                             + ("still rising, more paired speech should help)" if rise > 0.01 else "flat)"))
    return lines
