"""Fit a voice table: speech with paired mouth curves -> causal log-mel features -> ARKit mouth channels.

Four models compete under cross-validation, and the best (highest mean held-out r over the
channels) is kept:

* ``level``: each channel a line in the window's level (dBFS), the voice-level baseline the
  runtime had (``mouth = "voice"``);
* ``ridge``: ridge regression on the standardised features, alpha chosen by inner CV;
* ``kpls``: Ouzounis et al.'s kernel PLS (:class:`~facepuppet.offline.kpls.model.KernelPLS`, RBF
  kernel), components and width chosen by inner CV;
* ``blend``: the mean of ridge (its alpha chosen as ridge's) and gradient-boosted trees
  (:mod:`facepuppet.offline.voice.boost`, fixed settings): the trees read what a line in the
  features cannot (a vowel's openness is not linear in its band energies), the ridge half keeps
  their variance on 49 s of speech in check.

Folds are contiguous blocks of frames, never random frames: neighbouring frames of speech are
nearly the same sample, and a random split would score memory, not generalisation. Each
model's settings are chosen on the training folds only (an inner contiguous split), so the
held-out r of a fold never saw that fold. ``r`` of a channel is the mean over the folds of
Pearson's r on the fold (a fold where the channel does not move is left out of that mean).

Features of frame i (time i / fps) come from the samples before ``i / fps + lookahead_s``
(:func:`~facepuppet.runtime.voice.features.features_of`): causal with no look-ahead.
"""

from __future__ import annotations

import csv
import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.tables import hash_inputs
from facepuppet.runtime.mapping.channels import canonical, gesture_group
from facepuppet.runtime.voice.features import FeatureSpec, features_of
from facepuppet.runtime.voice.table import MAX_TRAIN, VoiceTable

from facepuppet.offline.gestures.speech_intensity import read_speech
from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.voice.boost import BoostSetting, fit_trees, predict_trees

CURVE_FPS = 30.0
MODEL_NAMES = ("level", "ridge", "kpls", "blend")
#: A model's setting: None (level), a ridge alpha (ridge, and blend's ridge half), or (components, gamma x
#: 1/n_features) of kernel PLS.
Setting = float | tuple[int, float] | None
RIDGE_ALPHAS = (10.0, 100.0, 1000.0)
BOOST = BoostSetting()
#: fit-voice's features: the runtime's log-mel layout, in dB relative to the speaker's running level (3 s), so
#: a table fitted on one recording's loudness reads another microphone's the same (bench voice: blend's mean r
#: on folds 4-5 moved 0.288 -> 0.250 with the test speech 6 dB louder in dBFS, and not at all relative)
VOICE_SPEC = FeatureSpec(level_ref_s=3.0)
KPLS_GRID = ((5, 0.1), (10, 0.1), (10, 0.3), (20, 0.1))  # (components, gamma x 1/n_features)
MIN_STD = 1e-3  # a channel that moves less than this in the training speech is not learned


@dataclass
class SpeechPair:
    """One speech recording with its mouth curves at CURVE_FPS: features X (n, n_features), curves Y (n, m)."""

    name: str
    X: np.ndarray
    Y: np.ndarray
    channels: tuple[str, ...]


def read_curves(curves_csv: str | os.PathLike, mapping_csv: str | os.PathLike) -> dict[str, np.ndarray]:
    """The mouth (lips group) ARKit channels of a curves CSV through a mapping sheet (arkit, sources, status).

    A sheet row with several ``;``-separated sources takes their maximum (the sheet's ``max``); rows whose
    status is not ``valid`` are skipped. Returns {ARKit name: (n,) float64}.
    """
    try:
        with open(curves_csv, newline="") as handle:
            rows = list(csv.reader(handle))
        header, data = rows[0], np.array(rows[1:], np.float64)
    except (UnicodeDecodeError, csv.Error, IndexError, ValueError) as exc:
        raise InputFileError(f"{curves_csv}: expected a header row, then rows of numbers ({exc})") from None
    if data.ndim != 2 or len(data) < 10 or data.shape[1] != len(header):
        raise InputFileError(f"{curves_csv}: expected a header row, then at least 10 rows of {len(header)} numbers")
    if not np.isfinite(data).all():
        raise InputFileError(f"{curves_csv}: NaN or infinite values")
    col = {n: i for i, n in enumerate(header)}
    try:
        with open(mapping_csv, newline="") as handle:
            mapping = list(csv.DictReader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputFileError(f"{mapping_csv}: not a readable CSV file ({exc})") from None
    out: dict[str, np.ndarray] = {}
    for number, row in enumerate(mapping, 2):
        if row.get("status") != "valid":
            continue
        arkit, sources = row.get("arkit"), row.get("sources")
        if not (isinstance(arkit, str) and isinstance(sources, str)):
            raise InputFileError(f"{mapping_csv}: row {number}: expected the columns arkit and sources")
        if gesture_group(arkit) != "lips":
            continue
        srcs = [s for s in sources.split(";") if s in col]
        if srcs:
            out[canonical(arkit)] = np.max(data[:, [col[s] for s in srcs]], axis=1)
    if not out:
        raise InputFileError(f"{curves_csv}: no mouth channel maps to ARKit through {mapping_csv}")
    return out


def read_pair(wav: str | os.PathLike, curves_csv: str | os.PathLike, mapping_csv: str | os.PathLike,
              spec: FeatureSpec, lookahead_s: float = 0.0) -> SpeechPair:
    """Features and curves of one speech pair, frame i at time i / CURVE_FPS."""
    curves = read_curves(curves_csv, mapping_csv)
    samples = read_speech(wav, rate=int(spec.sample_rate))
    n = len(next(iter(curves.values())))
    duration = len(samples) / spec.sample_rate
    if abs(duration - n / CURVE_FPS) > 1.0:
        raise InputFileError(f"{curves_csv}: {n} frames at {CURVE_FPS:g} fps ({n / CURVE_FPS:.2f} s) do not match "
                             f"{wav} ({duration:.2f} s)")
    X = features_of(samples, spec, np.arange(n) / CURVE_FPS + lookahead_s)
    names = tuple(sorted(curves))
    return SpeechPair(Path(curves_csv).stem, X, np.stack([curves[c] for c in names], 1), names)


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson's r of two series; NaN when either is constant."""
    a, b = a - a.mean(), b - b.mean()
    d = float(np.sqrt((a @ a) * (b @ b)))
    return float(a @ b) / d if d > 1e-12 else float("nan")


def contiguous_folds(n: int, k: int) -> list[np.ndarray]:
    return np.array_split(np.arange(n), k)


class Standardise:
    def __init__(self, X: np.ndarray) -> None:
        self.mean = X.mean(0)
        self.scale = np.maximum(X.std(0), 1e-3)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return (X - self.mean) / self.scale


def fit_model(name: str, X: np.ndarray, Y: np.ndarray, setting: Setting) -> Callable[[np.ndarray], np.ndarray]:
    """A fitted predictor X -> Y of one model and setting (standardisation fitted on X)."""
    st = Standardise(X)
    Z = st(X)
    ym = Y.mean(0)
    if name == "level":
        z = Z[:, -1:]
        w = np.linalg.lstsq(z, Y - ym, rcond=None)[0]
        return lambda Xs: st(Xs)[:, -1:] @ w + ym
    if name in ("ridge", "blend"):
        W = np.linalg.solve(Z.T @ Z + setting * np.eye(Z.shape[1]), Z.T @ (Y - ym))
        if name == "ridge":
            return lambda Xs: st(Xs) @ W + ym
        trees = fit_trees(Z, Y, BOOST)
        return lambda Xs: 0.5 * (st(Xs) @ W + ym) + 0.5 * predict_trees(st(Xs), *trees)
    p, g = setting
    model = KernelPLS(n_components=p, kernel="rbf", gamma=g / Z.shape[1]).fit(Z, Y)
    return lambda Xs: model.predict(st(Xs))


def settings_of(name: str) -> Sequence:
    return {"level": (None,), "ridge": RIDGE_ALPHAS, "kpls": KPLS_GRID, "blend": RIDGE_ALPHAS}[name]


def fold_r(P: np.ndarray, Y: np.ndarray, folds: list[np.ndarray]) -> np.ndarray:
    """Per channel, the mean over folds of r on the fold (NaN folds left out), shape (m,)."""
    r = np.array([[pearson(P[f, j], Y[f, j]) for j in range(Y.shape[1])] for f in folds])
    with np.errstate(all="ignore"):
        return np.nanmean(r, axis=0) if np.isfinite(r).any() else np.full(Y.shape[1], np.nan)


def choose_setting(name: str, X: np.ndarray, Y: np.ndarray, k: int = 4) -> Setting:
    """The setting of ``name`` with the best mean r under a contiguous k-fold split of (X, Y) (blend's: its
    ridge half's, chosen as ridge's; the trees' settings are fixed)."""
    if name == "blend":
        name = "ridge"
    grid = settings_of(name)
    if len(grid) == 1:
        return grid[0]
    folds = contiguous_folds(len(X), k)
    best, best_r = grid[0], -np.inf
    for s in grid:
        P = np.zeros_like(Y)
        for f in folds:
            train = np.setdiff1d(np.arange(len(X)), f)
            P[f] = fit_model(name, X[train], Y[train], s)(X[f])
        r = float(np.nanmean(fold_r(P, Y, folds)))
        if r > best_r:
            best, best_r = s, r
    return best


def cross_validate(X: np.ndarray, Y: np.ndarray, k: int = 5, models: Sequence[str] = MODEL_NAMES,
                   test_folds: Sequence[int] | None = None,
                   progress: Callable[[str], None] | None = None) -> dict[str, dict]:
    """Held-out r per model: settings chosen on each training part only, scored on its held-out fold.

    ``test_folds``: the fold indices scored (default all); with e.g. (3, 4) the settings are chosen on
    folds 0..2 once and the held-out folds are never looked at before (the "design vs measure" split).
    Returns {model: {"r": (m,) per channel, "setting": per fold, "pred": (n, m) held-out predictions}}.
    """
    folds = contiguous_folds(len(X), k)
    tests = list(range(k)) if test_folds is None else list(test_folds)
    out = {}
    for name in models:
        P = np.full_like(Y, np.nan)
        chosen = []
        for i in tests:
            f = folds[i]
            if test_folds is None:
                train = np.setdiff1d(np.arange(len(X)), f)
            else:
                train = np.concatenate([folds[j] for j in range(k) if j not in tests])
            s = choose_setting(name, X[train], Y[train])
            chosen.append(s)
            P[f] = fit_model(name, X[train], Y[train], s)(X[f])
            if progress is not None:
                progress(f"{name} fold {i + 1}/{k}")
        scored = [folds[i] for i in tests]
        out[name] = {"r": fold_r(P, Y, scored), "setting": chosen, "pred": P}
    return out


def to_table(name: str, setting: Setting, X: np.ndarray, Y: np.ndarray, channels: Sequence[str], spec: FeatureSpec,
             lookahead_s: float, gate_db: float, metadata: dict) -> VoiceTable:
    """The runtime table of ``name`` fitted on all of (X, Y)."""
    st = Standardise(X)
    Z = st(X)
    ym = Y.mean(0)
    common = dict(outputs=tuple(channels), spec=spec, model=name, feature_mean=st.mean, feature_scale=st.scale,
                  lookahead_s=lookahead_s, gate_db=gate_db, metadata=metadata)
    if name == "level":
        W = np.zeros((X.shape[1], Y.shape[1]))
        W[-1] = np.linalg.lstsq(Z[:, -1:], Y - ym, rcond=None)[0][0]
        return VoiceTable(output_mean=ym, coef=W, **common)
    if name in ("ridge", "blend"):
        W = np.linalg.solve(Z.T @ Z + setting * np.eye(Z.shape[1]), Z.T @ (Y - ym))
        if name == "ridge":
            return VoiceTable(output_mean=ym, coef=W, **common)
        base, feature, threshold, value = fit_trees(Z, Y, BOOST)  # halves of both models, summed at run time
        return VoiceTable(output_mean=0.5 * (ym + base), coef=0.5 * W, tree_feature=feature,
                          tree_threshold=threshold, tree_value=0.5 * value, **common)
    if len(Z) > MAX_TRAIN:  # bound the table's size and its cost per hop: every k-th frame
        keep = np.linspace(0, len(Z) - 1, MAX_TRAIN).round().astype(int)
        Z, Y = Z[keep], Y[keep]
    p, g = setting
    model = KernelPLS(n_components=p, kernel="rbf", gamma=g / Z.shape[1]).fit(Z, Y)
    a = model.export_arrays()
    return VoiceTable(output_mean=a["target_mean"], train_inputs=a["train_inputs"], dual_coef=a["dual_coef"],
                      kernel_col_mean=a["kernel_col_mean"], kernel_grand_mean=float(a["kernel_grand_mean"]),
                      gamma=float(a["gamma"]), **common)


def gate_of(X: np.ndarray) -> float:
    """The level under which the mouth closes: 6 dB over the training speech's noise floor (its 10th-percentile
    window level), never below -70 dB (dBFS, or relative to the running level where the features are)."""
    return float(max(np.percentile(X[:, -1], 10.0) + 6.0, -70.0))


def fit_voice(pairs: Sequence[tuple[Path, Path, Path]], spec: FeatureSpec | None = None, lookahead_s: float = 0.0,
              folds: int = 5, models: Sequence[str] = MODEL_NAMES,
              progress: Callable[[str], None] | None = None) -> tuple[VoiceTable, dict]:
    """Cross-validate the models on the speech pairs, keep the best, fit it on all of them.

    pairs : (WAV, curves CSV, mapping CSV) triples, concatenated in order
    Returns (table, report) where report holds per-model per-channel held-out r.
    """
    spec = spec or VOICE_SPEC
    if not 0.0 <= lookahead_s <= 0.5:
        raise UsageError(f"--lookahead: expected 0..500 ms, got {lookahead_s * 1000:g} ms")
    read = [read_pair(w, c, m, spec, lookahead_s) for w, c, m in pairs]
    channels = [c for c in read[0].channels if all(c in p.channels for p in read)]
    X = np.concatenate([p.X for p in read])
    Y = np.concatenate([p.Y[:, [p.channels.index(c) for c in channels]] for p in read])
    moving = Y.std(0) >= MIN_STD
    channels = [c for c, keep in zip(channels, moving) if keep]
    Y = Y[:, moving]
    if not channels:
        raise InputFileError(f"{pairs[0][1]}: no mouth channel moves (std >= {MIN_STD}) in the speech given")
    if len(X) < 10 * folds:
        raise InputFileError(f"{pairs[0][1]}: {len(X)} frames are too few for {folds}-fold cross-validation")
    cv = cross_validate(X, Y, folds, models, progress=progress)
    score = {name: float(np.nanmean(v["r"])) for name, v in cv.items()}
    best = max(score, key=score.get)
    setting = choose_setting(best, X, Y)
    report = {"channels": list(channels), "frames": int(len(X)), "folds": folds, "best": best,
              "held_out_r": {name: {c: float(r) for c, r in zip(channels, v["r"])} for name, v in cv.items()},
              "mean_r": score, "setting": _jsonable(setting)}
    gate = gate_of(X)
    meta = {"settings": {"pairs": [[str(w), str(c), str(m)] for w, c, m in pairs], "folds": folds,
                         "setting": _jsonable(setting), "gate_db": gate,
                         **({"trees": dataclasses.asdict(BOOST)} if best == "blend" else {}),
                         "features": {"sample_rate": spec.sample_rate, "window_s": spec.window_s,
                                      "hop_s": spec.hop_s, "n_mels": spec.n_mels, "n_taps": spec.n_taps,
                                      "step": spec.step, "fmin": spec.fmin, "fmax": spec.fmax,
                                      "level_ref_s": spec.level_ref_s}},
            "metrics": {"held_out_r": report["held_out_r"], "mean_r": score},
            "input_hash": hash_inputs(*[p for triple in pairs for p in triple])}
    table = to_table(best, setting, X, Y, channels, spec, lookahead_s, gate, meta)
    return table, report


def _jsonable(setting):
    if setting is None:
        return None
    if isinstance(setting, tuple):
        return {"components": int(setting[0]), "gamma_x_features": float(setting[1])}
    return {"alpha": float(setting)}


def report_lines(report: dict) -> list[str]:
    """The per-channel held-out r table of a fit (one column per model, the kept one marked)."""
    names = list(report["held_out_r"])
    head = f"  {'channel':<22}" + "".join(f"{(n + ('*' if n == report['best'] else '')):>10}" for n in names)
    lines = [f"held-out r ({report['folds']} contiguous folds, {report['frames']} frames; * kept):", head]
    for c in report["channels"]:
        lines.append(f"  {c:<22}" + "".join(f"{report['held_out_r'][n][c]:>10.3f}" for n in names))
    lines.append(f"  {'mean':<22}" + "".join(f"{report['mean_r'][n]:>10.3f}" for n in names))
    best, r = report["best"], report["held_out_r"]
    if best != "level" and "level" in r:
        weak = [c for c in report["channels"] if not r[best][c] > r["level"][c]]
        if weak:
            lines.append(f"warning: {', '.join(weak)}: held-out r of {best} not above the voice level's; on speech "
                         "this table never saw they follow the voice no better than the level does (more paired "
                         "speech may not help: on the kit's take, 10 to 39 s of training did not lift these two, "
                         "bench voice's learning curve; with --voice-mode loss, the default, a tracker drives "
                         "them while it sees the face)")
    return lines
