"""Gradient-boosted regression trees for the voice table's ``blend`` model, fitted with NumPy alone.

Squared loss, so each tree fits the current residual: a tree of ``depth`` levels is grown level by
level over all its nodes at once. Features are cut into at most ``n_bins`` quantile bins once (the
cuts halfway between neighbouring distinct quantiles); at a node, the split of a feature at a cut
gains ``G_L² / (N_L + λ) + G_R² / (N_R + λ) − G² / (N + λ)`` (G the residual sum, N the count),
both sides holding at least ``min_leaf`` rows; the node takes the best, or does not split
(threshold :data:`~facepuppet.runtime.voice.trees.NEVER`) when none gains. A leaf holds
``rate · G / (N + λ)``. The trees come out complete, in the heap order the run-time evaluator reads
(:mod:`facepuppet.runtime.voice.trees`), and the features are compared as float32 values, as the
evaluator holds them, so the fit's predictions and the run time's agree exactly.

This is the method of Friedman's gradient boosting with second-order leaf values and L2 shrinkage
(the form popularised by XGBoost and LightGBM), written for a few thousand rows and ~100 features.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.voice.trees import NEVER, predict_rows


@dataclass(frozen=True)
class BoostSetting:
    """n_trees per output, learning rate, tree depth, rows per leaf at least, L2 shrinkage λ, bins per feature."""

    n_trees: int = 150
    rate: float = 0.06
    depth: int = 3
    min_leaf: int = 20
    l2: float = 1.0
    n_bins: int = 32


def cuts_of(Z: np.ndarray, n_bins: int) -> list[np.ndarray]:
    """Per feature, the increasing thresholds between its quantile bins (fewer for a feature with few values)."""
    cuts = []
    for j in range(Z.shape[1]):
        q = np.unique(np.quantile(Z[:, j], np.linspace(0.0, 1.0, n_bins + 1)))
        cuts.append(0.5 * (q[:-1] + q[1:]) if len(q) > 1 else np.zeros(0))
    return cuts


def fit_trees(Z: np.ndarray, Y: np.ndarray, setting: BoostSetting = BoostSetting()) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Boosted trees for each column of Y on the standardised features Z.

    Z : (n, n_features), Y : (n, n_outputs)
    Returns (base (n_outputs,) float64, feature (n_trees, n_internal) int32, threshold (n_trees, n_internal)
    float64, value (n_trees, n_leaves) float32), trees output by output; a prediction is base + the tree sums.
    """
    Z = np.asarray(Z, np.float32).astype(np.float64)  # compared as the run time holds it
    Y = np.asarray(Y, np.float64)
    n, p = Z.shape
    s = setting
    cuts = cuts_of(Z, s.n_bins)
    B = s.n_bins + 1  # bins per feature: up to n_bins cuts
    # bin b of a value: how many cuts lie below it; "goes right at cut k" is then b > k
    Xb = np.stack([np.searchsorted(c, Z[:, j], side="left") for j, c in enumerate(cuts)], 1)
    jb = np.arange(p)[None, :] * B + Xb  # (n, p) index of (feature, bin)
    n_int, n_leaf = 2 ** s.depth - 1, 2 ** s.depth
    m = Y.shape[1]
    feature = np.zeros((m * s.n_trees, n_int), np.int32)
    threshold = np.full((m * s.n_trees, n_int), NEVER)
    value = np.zeros((m * s.n_trees, n_leaf), np.float32)
    base = Y.mean(axis=0)
    valid_cut = np.zeros((p, B - 1), bool)
    for j, c in enumerate(cuts):
        valid_cut[j, :len(c)] = True
    for o in range(m):
        pred = np.full(n, base[o])
        for t in range(s.n_trees):
            row = o * s.n_trees + t
            resid = Y[:, o] - pred
            node = np.zeros(n, np.intp)
            for d in range(s.depth):
                k = 2 ** d  # nodes on this level
                idx = (node[:, None] * (p * B) + jb).ravel()
                G = np.bincount(idx, np.repeat(resid, p), minlength=k * p * B).reshape(k, p, B)
                N = np.bincount(idx, minlength=k * p * B).reshape(k, p, B).astype(np.float64)
                GL, NL = np.cumsum(G, 2)[:, :, :-1], np.cumsum(N, 2)[:, :, :-1]
                Gt, Nt = G[:, :1].sum(2, keepdims=True), N[:, :1].sum(2, keepdims=True)
                GR, NR = Gt - GL, Nt - NL
                gain = GL ** 2 / (NL + s.l2) + GR ** 2 / (NR + s.l2) - Gt ** 2 / (Nt + s.l2)
                gain[(NL < s.min_leaf) | (NR < s.min_leaf) | ~valid_cut[None]] = -np.inf
                flat = gain.reshape(k, -1)
                best = np.argmax(flat, axis=1)
                ok = flat[np.arange(k), best] > 1e-12
                bf, bc = best // (B - 1), best % (B - 1)
                heap = k - 1 + np.arange(k)  # heap positions of this level's nodes
                feature[row, heap] = np.where(ok, bf, 0)
                threshold[row, heap[ok]] = [cuts[f][c] for f, c in zip(bf[ok], bc[ok])]
                go_right = ok[node] & (Xb[np.arange(n), bf[node]] > bc[node])
                node = 2 * node + go_right
            sums = np.bincount(node, resid, minlength=n_leaf)
            counts = np.bincount(node, minlength=n_leaf)
            value[row] = s.rate * sums / (counts + s.l2)
            pred += value[row][node].astype(np.float64)
    return base, feature, threshold, value


def predict_trees(Z: np.ndarray, base: np.ndarray, feature: np.ndarray, threshold: np.ndarray,
                  value: np.ndarray) -> np.ndarray:
    """base + the tree sums for rows Z: shape (k, n_outputs), the run time's own comparisons."""
    return base + predict_rows(Z, feature, threshold, value, len(base))
