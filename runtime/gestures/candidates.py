"""The candidate index of the gesture MRF: which reference frames a group may pick next (Ju & Lee §5.1).

The full §5.1 distance is evaluated only on a small candidate set per group,
precomputed per reference frame p (the last pick): the successor p+1 and the
``n_neighbours`` frames whose continuity windows are nearest to p+1's (exact,
brute force at construction), plus ``n_speech`` frames from the bin of the
current intensity (:data:`N_BINS` bins over [SILENCE_Z, -SILENCE_Z]).
Used by :class:`~facepuppet.runtime.gestures.synth.GestureSynth`.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.gestures.speaker_normaliser import SILENCE_Z

N_BINS = 24       # intensity bins of the speech candidates, over [SILENCE_Z, -SILENCE_Z]


def intensity_bin(a: np.ndarray) -> np.ndarray:
    """Bin (0 .. N_BINS - 1) of normalised intensities ``a`` (z-score), int array."""
    return np.clip(((np.asarray(a) - SILENCE_Z) / (-2 * SILENCE_Z) * N_BINS).astype(int), 0, N_BINS - 1)


def nearest_windows(windows: np.ndarray, rows: np.ndarray, k: int, exclude: int, chunk: int = 512) -> np.ndarray:
    """Row indices (frames ``rows``) of the ``k`` nearest windows to each window, frames >= ``exclude`` apart.

    windows : (len(rows), D) float, one per frame of ``rows``; exact squared Euclidean; -1 pads.
    """
    w = windows.astype(np.float32)
    sq = np.einsum("ij,ij->i", w, w)
    out = np.zeros((len(rows), k), np.int64)
    for s in range(0, len(rows), chunk):
        d = sq[s:s + chunk, None] + sq[None, :] - 2.0 * (w[s:s + chunk] @ w.T)
        near = np.abs(rows[s:s + chunk, None] - rows[None, :]) < exclude  # no jump within the own run
        d[near] = np.inf
        kk = min(k, len(rows) - 1)
        part = np.argpartition(d, kk - 1, axis=1)[:, :kk] if kk > 0 else np.zeros((len(d), 0), np.int64)
        order = np.take_along_axis(d, part, 1).argsort(1, kind="stable")
        best = np.take_along_axis(part, order, 1)
        best_d = np.take_along_axis(d, best, 1)
        out[s:s + chunk] = -1
        out[s:s + chunk, :kk] = np.where(np.isfinite(best_d), rows[best], -1)
    return out


def build_candidates(desc: np.ndarray, valid_mask: np.ndarray, intensity: np.ndarray, last: np.ndarray,
                     history: int, n_neighbours: int, n_speech: int) -> np.ndarray:
    """Candidate rows per group: for last pick p, [p+1, nearest windows to p+1's]; per intensity bin, frames.

    Parameters
    ----------
    desc : (n, G, R) float, each group's continuity features x(i) in its principal axes
    valid_mask : (G, n) bool, frames each group may show (h frames of history in its take)
    intensity : (n,) float, reference speech intensity s_ref(i), z-score
    last : (n,) bool, whether frame i is the last of its take
    history : int, h
    n_neighbours, n_speech : int, jump candidates per frame by continuity, and per intensity bin

    Returns
    -------
    T : (G, n + N_BINS, max(n_neighbours + 1, n_speech)) int64, frame indices; row p < n: after a pick p,
        row n + b: intensity bin b; frame n is the sentinel (never wins)
    """
    G, n, h = valid_mask.shape[0], len(last), history
    K = n_neighbours + 1
    T = np.full((G, n + N_BINS, max(K, n_speech)), n, np.int64)  # frame n: the sentinel (never wins)
    bins = intensity_bin(intensity)
    for k in range(G):
        valid = np.flatnonzero(valid_mask[k])
        win = desc[np.clip(valid[:, None] + np.arange(-h + 1, 1), 0, n - 1), k].reshape(len(valid), -1)
        near = nearest_windows(win, valid, n_neighbours, exclude=h)  # windows x(i-h+1 .. i) like p+1's history
        row_of = np.full(n, -1)
        row_of[valid] = np.arange(len(valid))
        succ = np.where(~last[:-1] & valid_mask[k, 1:], np.arange(1, n), -1)
        succ = np.r_[succ, -1]
        for p in range(n):
            s = succ[p]
            if s >= 0:
                T[k, p, 0] = s
                jumps = near[row_of[p]] + 1 if row_of[p] >= 0 else near[row_of[s]]  # j: x(j-h..j-1) ≈ x(p-h+1..p)
            else:  # end of a take (or invalid frame): only jumps, to frames whose history is like p's
                anchor = p if row_of[p] >= 0 else valid[0]
                jumps = near[row_of[anchor]] + 1
            jumps = jumps[(jumps > 0) & (jumps < n)]
            jumps = jumps[valid_mask[k, jumps] & (jumps != s)][:K - 1]
            T[k, p, 1:1 + len(jumps)] = jumps
        filled = np.unique(bins[valid])
        for b in range(N_BINS):  # an empty bin takes the frames of the nearest filled bin
            members = valid[bins[valid] == filled[np.argmin(np.abs(filled - b))]]
            pick = members[np.unique(np.linspace(0, len(members) - 1, n_speech).round().astype(int))]
            T[k, n + b, :len(pick)] = pick
    return T
