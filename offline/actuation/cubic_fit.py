"""Cubic deformation functions from actuations (Shin & Lee 2009, §5, eqs 2-4).

Paper symbols -> code names:

    s_k             actuation k of a frame                      s[t, k]          (n_frames, K)
    x_j             one output coordinate (marker axis, or      y[t, j]          (n_frames, n_out)
                    a character weight in §6.2)
    a_jk, b_jk, c_jk cubic coefficients                          coef[0|1|2, k, j] (3, K, n_out)
    Phi             design matrix [s^3 | s^2 | s]                design(s)        (n_frames, 3K)

Eq 2-3: x_j(s) = sum_k a_jk s_k^3 + b_jk s_k^2 + c_jk s_k, no constant term
(s = 0 is the neutral, where every displacement is 0).
Eq 4: the coefficients of all outputs at once by linear least squares,
min ||Phi theta_j - x_j||^2 for every j with one factorisation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def design(s: np.ndarray, degree: int = 3) -> np.ndarray:
    """Phi = [s^3 | s^2 | s] (degree 3) or [s] (degree 1); ndarray of shape (n_frames, degree*K), float64."""
    s = np.asarray(s, dtype=np.float64)
    if degree == 1:
        return s
    return np.concatenate([s ** 3, s ** 2, s], axis=1)          # Shin & Lee eq. 2 terms


RIDGE_AB_STRENGTHS = (0.0, 1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0)   # candidates for the a, b ridge


def _solve(phi: np.ndarray, y: np.ndarray, ridge: float, penalty: np.ndarray | None = None) -> np.ndarray:
    """Least squares (ridge-stabilised normal equations), all columns of ``y`` at once (eq. 4).

    ``penalty`` (n_terms,) adds a per-term Tikhonov weight, relative to the mean diagonal like ``ridge``.
    """
    gram = phi.T @ phi
    scale = max(float(np.trace(gram)) / len(gram), 1e-12)
    gram[np.diag_indices_from(gram)] += ridge * scale + (0.0 if penalty is None else penalty * scale)
    return np.linalg.solve(gram, phi.T @ y)                     # Shin & Lee eq. 4


def fit_polynomial(s: np.ndarray, y: np.ndarray, degree: int = 3, ridge: float = 1e-8,
                   ridge_ab: float = 0.0) -> np.ndarray:
    """Fit x_j(s) for every output column of ``y``; NaN targets are left out of their column's fit.

    Parameters
    ----------
    s : ndarray of shape (n_frames, K), float
    y : ndarray of shape (n_frames, n_out), float, NaN = missing sample
    degree : 3 (cubic, eqs 2-4) or 1 (linear model, for comparison)
    ridge : float, Tikhonov weight relative to the mean diagonal of Phi^T Phi
    ridge_ab : float, extra weight on the cubic and quadratic terms only (a, b; degree 3): shrinks the
        cubic towards the linear model where the data do not support the curvature

    Returns
    -------
    coef : ndarray of shape (3, K, n_out) for degree 3 ([a, b, c]) or (1, K, n_out) for degree 1, float64
    """
    if degree not in (1, 3):
        raise ValueError(f"degree: expected 1 or 3, got {degree!r}")
    if not ridge_ab >= 0:
        raise ValueError(f"ridge_ab: expected a number >= 0, got {ridge_ab!r}")
    s = np.asarray(s, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if s.ndim != 2 or y.ndim != 2 or len(s) != len(y):
        raise ValueError(f"fit_polynomial: expected s (n, K) and y (n, n_out), got {s.shape} and {y.shape}")
    if not np.isfinite(s).all():
        raise ValueError("fit_polynomial: s contains NaN or infinity")
    phi = design(s, degree)
    n_terms = phi.shape[1]
    k = s.shape[1]
    penalty = np.r_[np.full(2 * k, ridge_ab), np.zeros(k)] if degree == 3 and ridge_ab > 0 else None
    out = np.zeros((n_terms, y.shape[1]))
    missing = np.isnan(y)
    full = ~missing.any(axis=0)
    if full.any():
        out[:, full] = _solve(phi, y[:, full], ridge, penalty)
    for j in np.flatnonzero(~full):                             # columns with gaps: their own rows
        rows = ~missing[:, j]
        if rows.sum() >= n_terms:
            out[:, j] = _solve(phi[rows], y[rows, j:j + 1], ridge, penalty)[:, 0]
    return out.reshape(degree if degree == 3 else 1, s.shape[1], y.shape[1])


def evaluate(coef: np.ndarray, s: np.ndarray) -> np.ndarray:
    """x(s) for coefficients from :func:`fit_polynomial`; ndarray of shape (n_frames, n_out), float64."""
    coef = np.asarray(coef, dtype=np.float64)
    degree = 3 if coef.shape[0] == 3 else 1
    return design(np.atleast_2d(s), degree) @ coef.reshape(-1, coef.shape[2])   # Shin & Lee eq. 2


def holdout_split(n_frames: int, fraction: float = 0.2, blocks: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Boolean train/test masks: the last ``fraction`` of each of ``blocks`` contiguous blocks is held out.

    Contiguous pieces, so held-out frames are not next-door neighbours of training frames.
    """
    test = np.zeros(n_frames, dtype=bool)
    edges = np.linspace(0, n_frames, blocks + 1).astype(int)
    for lo, hi in zip(edges[:-1], edges[1:]):
        test[hi - max(1, int(round((hi - lo) * fraction))):hi] = True
    return ~test, test


def point_rms(coef: np.ndarray, s: np.ndarray, y: np.ndarray, n_points: int) -> float:
    """RMS 3-D point distance between :func:`evaluate` and ``y`` (n_frames, n_points*3), NaN points left out."""
    err = evaluate(coef, s) - y
    d2 = np.nansum(err.reshape(len(err), n_points, 3) ** 2, axis=2)
    valid = ~np.isnan(y).reshape(len(err), n_points, 3).any(axis=2)
    return float(np.sqrt(d2[valid].mean())) if valid.any() else float("nan")


def choose_ridge_ab(s: np.ndarray, y: np.ndarray, n_points: int, strengths: Sequence[float] = RIDGE_AB_STRENGTHS,
                    fraction: float = 0.2) -> tuple[float, list[dict]]:
    """The ``ridge_ab`` of least held-out error on a split of the given frames (:func:`holdout_split`).

    Returns (strength, [{"ridge_ab", "rms"}, ...]) with the RMS point error (units) of each candidate.
    """
    train, test = holdout_split(len(s), fraction)
    table = [{"ridge_ab": float(r), "rms": point_rms(fit_polynomial(s[train], y[train], 3, ridge_ab=r),
                                                     s[test], y[test], n_points)} for r in strengths]
    best = min(table, key=lambda row: row["rms"])
    return best["ridge_ab"], table


def holdout_errors(s: np.ndarray, y: np.ndarray, n_points: int, fraction: float = 0.2) -> dict:
    """Held-out RMS point error of the linear model, the plain cubic and the cubic with a chosen a, b ridge.

    s : ndarray of shape (n_frames, K); y : ndarray of shape (n_frames, n_points*3), units, NaN = missing
    The ridge strength is chosen on an inner split of the training frames only, so the held-out
    frames judge it fairly. Returns {"linear_rms", "cubic_rms", "cubic_ridge_rms", "ridge_ab",
    "n_train", "n_test"}; RMS of the 3-D point distance, units.
    """
    train, test = holdout_split(len(s), fraction)
    ridge_ab, _ = choose_ridge_ab(s[train], y[train], n_points, fraction=fraction)
    return {"n_train": int(train.sum()), "n_test": int(test.sum()), "ridge_ab": ridge_ab,
            "linear_rms": point_rms(fit_polynomial(s[train], y[train], 1), s[test], y[test], n_points),
            "cubic_rms": point_rms(fit_polynomial(s[train], y[train], 3), s[test], y[test], n_points),
            "cubic_ridge_rms": point_rms(fit_polynomial(s[train], y[train], 3, ridge_ab=ridge_ab), s[test],
                                         y[test], n_points)}
