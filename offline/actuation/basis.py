"""Actuation parameters from marker displacements (Shin & Lee 2009, §4).

Paper symbols -> code names:

    d_i(t)      displacement of marker i from neutral          disp[t, i]           (n_frames, n_markers, 3)
    p           local maxima of |d_i(t)| over t                peaks (per marker)
    v_ic        class axis c of marker i (unit sphere)          axes_[c], axis_marker_[c]
    x_ic(t)     actuation signal of class c (projection)        signals[t, c]        (n_frames, n_classes)
    W           ICA unmixing (sign/scale normalised)            unmixing_            (K, n_classes)
    s(t)        actuation parameters                            s[t]                 (n_frames, K)

The signals are one-sided projections on the class axes, weighted by a soft
membership so a marker whose direction moves from one class to another hands
over smoothly. FastICA (scikit-learn) mixes all markers' signals into K
actuations; signs and scales are then fixed so that s = 0 is the neutral
frame and s = 1 a strong actuation (the ``strong_quantile`` of the take).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.signal import argrelmax

from facepuppet.runtime.errors import UsageError

# Why these defaults: a bandwidth of 0.5 on the unit sphere is ~29 degrees
# between directions, so up/down or in/out of one marker become separate
# classes while noise around one direction stays together.
DEFAULT_BANDWIDTH = 0.5
DEFAULT_HANDOVER_POWER = 4.0


def neutral_frame(markers: np.ndarray) -> int:
    """The frame closest to each marker's median position (the face at rest most of the take).

    markers : ndarray of shape (n_frames, n_markers, 3), float, head coordinates
    """
    med = np.nanmedian(markers, axis=0)
    dist = np.nanmean(np.sum((markers - med) ** 2, axis=2), axis=1)
    dist[~np.isfinite(markers).all(axis=(1, 2))] = np.inf
    return int(np.argmin(dist))


def marker_peaks(magnitude: np.ndarray, order: int, floor: float, fraction: float, max_peaks: int) -> np.ndarray:
    """Frames of local maxima of one marker's displacement magnitude (Shin & Lee §4.1).

    magnitude : ndarray of shape (n_frames,), float; NaN is treated as 0
    Returns indices of maxima above ``max(floor, fraction * max)``, at most ``max_peaks`` (largest kept).
    """
    mag = np.nan_to_num(magnitude, nan=0.0)
    idx = argrelmax(np.r_[0.0, mag, 0.0], order=order, mode="clip")[0] - 1
    idx = idx[(idx >= 0) & (idx < len(mag))]
    keep = idx[mag[idx] > max(floor, fraction * float(mag.max(initial=0.0)))]
    if len(keep) > max_peaks:
        keep = keep[np.argsort(mag[keep])[-max_peaks:]]
    return np.sort(keep)


def mean_shift(points: np.ndarray, bandwidth: float, max_iter: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """Flat-kernel mean-shift, every point a seed, all seeds moved at once (NumPy).

    Same procedure as scikit-learn's ``MeanShift`` (flat kernel, modes merged
    when closer than the bandwidth, the mode with more points kept, every point
    labelled with its nearest mode); vectorised because the per-seed loop
    there costs ~10 ms a seed. ``class_axes(method="sklearn")`` runs the
    library instead; the tests check both give the same classes.

    points : ndarray of shape (n, d), float
    Returns centres (n_clusters, d) float64 and labels (n,) int64.
    """
    x = np.asarray(points, dtype=np.float64)
    seeds = x.copy()
    for _ in range(max_iter):
        near = (np.sum((seeds[:, None, :] - x[None, :, :]) ** 2, axis=2) <= bandwidth ** 2).astype(np.float64)
        moved = near @ x / near.sum(axis=1, keepdims=True)
        done = np.max(np.sum((moved - seeds) ** 2, axis=1)) < (1e-3 * bandwidth) ** 2
        seeds = moved
        if done:
            break
    strength = (np.sum((seeds[:, None, :] - x[None, :, :]) ** 2, axis=2) <= bandwidth ** 2).sum(axis=1)
    centres: list[np.ndarray] = []
    for i in np.argsort(-strength, kind="stable"):
        if all(np.sum((seeds[i] - c) ** 2) > bandwidth ** 2 for c in centres):
            centres.append(seeds[i])
    centres_arr = np.asarray(centres)
    labels = np.argmin(np.sum((x[:, None, :] - centres_arr[None]) ** 2, axis=2), axis=1)
    return centres_arr, labels


def class_axes(disp: np.ndarray, bandwidth: float = DEFAULT_BANDWIDTH, peak_order: int = 3,
               floor_fraction: float = 0.05, peak_fraction: float = 0.2, min_members: int = 2,
               max_peaks: int = 200, method: str = "numpy") -> tuple[np.ndarray, np.ndarray]:
    """Per-marker class axes from mean-shift on the directions of displacement peaks (§4.1).

    Parameters
    ----------
    disp : ndarray of shape (n_frames, n_markers, 3), float, units, displacement from neutral
    method : "numpy" (:func:`mean_shift`, per marker) or "sklearn" (``sklearn.cluster.MeanShift``)

    Returns
    -------
    axes : ndarray of shape (n_classes, 3), float64, unit vectors, grouped by marker
    axis_marker : ndarray of shape (n_classes,), int64, the marker each axis belongs to
    """
    if method not in ("numpy", "sklearn"):
        raise ValueError(f"class_axes method: expected 'numpy' or 'sklearn', got {method!r}")
    mag = np.linalg.norm(disp, axis=2)
    floor = floor_fraction * float(np.nanpercentile(mag, 99.9))
    axes, axis_marker = [], []
    for i in range(disp.shape[1]):
        peaks = marker_peaks(mag[:, i], peak_order, floor, peak_fraction, max_peaks)
        if len(peaks) < min_members:
            continue
        dirs = disp[peaks, i] / mag[peaks, i, None]             # peak directions on the unit sphere
        if method == "sklearn":
            from sklearn.cluster import MeanShift
            from threadpoolctl import threadpool_limits

            # one thread: on a few dozen points the thread pools' start-up costs ~0.5 s a call on a busy machine
            with threadpool_limits(limits=1):
                labels = MeanShift(bandwidth=bandwidth).fit(dirs).labels_
        else:
            labels = mean_shift(dirs, bandwidth)[1]
        for label in np.unique(labels):
            members = labels == label
            if members.sum() < min_members:
                continue
            centre = dirs[members].mean(axis=0)                 # class axis v_ic
            axes.append(centre / np.linalg.norm(centre))
            axis_marker.append(i)
    if not axes:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.asarray(axes), np.asarray(axis_marker, dtype=np.int64)


def actuation_signals(disp: np.ndarray, axes: np.ndarray, axis_marker: np.ndarray,
                      power: float = DEFAULT_HANDOVER_POWER) -> np.ndarray:
    """Signals x_ic(t): projection on class axes with smooth hand-over between a marker's classes (§4.2).

    x_ic = m_ic * max(d_i . v_ic, 0) with membership m_ic = cos_c^p / sum_c' cos_c'^p over the
    marker's classes (cos clipped at 0), continuous in d_i.

    disp : ndarray of shape (n_frames, n_markers, 3), float, units
    Returns ndarray of shape (n_frames, n_classes), float64, units (NaN where the marker is occluded)
    """
    d = disp[:, axis_marker]                                   # (n_frames, n_classes, 3)
    proj = np.einsum("fcx,cx->fc", d, axes)                    # d_i . v_ic
    norm = np.linalg.norm(d, axis=2)
    cos = np.clip(proj / np.maximum(norm, 1e-12), 0.0, 1.0) ** power
    total = np.zeros((len(disp), disp.shape[1]))
    np.add.at(total.T, axis_marker, cos.T)
    member = cos / np.maximum(total[:, axis_marker], 1e-12)
    return member * np.maximum(proj, 0.0)


class ActuationModel:
    """Signals -> K actuations by FastICA, normalised so s = 0 is neutral and s = 1 strong.

    Parameters
    ----------
    n_components : int, K (Shin & Lee use 13)
    bandwidth : float, mean-shift bandwidth on the unit sphere
    handover_power : float, sharpness of the hand-over between a marker's classes
    strong_quantile : float, the quantile of each actuation that becomes s = 1
    random_state : int, FastICA seed (fits are deterministic)

    Attributes (after fit)
    ----------------------
    axes_ : ndarray of shape (n_classes, 3), float64
    axis_marker_ : ndarray of shape (n_classes,), int64
    unmixing_ : ndarray of shape (K, n_classes), float64, s = unmixing_ @ x (x = signals of a frame)
    """

    def __init__(self, n_components: int = 13, bandwidth: float = DEFAULT_BANDWIDTH,
                 handover_power: float = DEFAULT_HANDOVER_POWER, strong_quantile: float = 0.99,
                 random_state: int = 0) -> None:
        self.n_components = n_components
        self.bandwidth = bandwidth
        self.handover_power = handover_power
        self.strong_quantile = strong_quantile
        self.random_state = random_state

    def fit(self, disp: np.ndarray) -> ActuationModel:
        """Learn class axes and the unmixing from displacements (n_frames, n_markers, 3), float, units."""
        from sklearn.decomposition import FastICA

        k = self.n_components
        if not isinstance(k, (int, np.integer)) or k < 1:
            raise UsageError(f"n_components (K): expected a positive integer, got {k!r}")
        self.axes_, self.axis_marker_ = class_axes(disp, self.bandwidth)
        x = actuation_signals(disp, self.axes_, self.axis_marker_, self.handover_power)
        x = x[np.isfinite(x).all(axis=1)]
        n_classes = x.shape[1]
        if k > min(n_classes, len(x)):
            raise UsageError(
                f"K = {k} is larger than possible: the take yields {n_classes} actuation signals "
                f"(marker classes) over {len(x)} complete frames; use K <= {min(n_classes, len(x))}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", category=UserWarning)  # FastICA's whiten notice
            ica = FastICA(n_components=k, whiten="unit-variance", whiten_solver="eigh",
                          random_state=self.random_state, max_iter=400, tol=1e-4)
            s = ica.fit_transform(x)
        self.converged_ = ica.n_iter_ < ica.max_iter
        if not self.converged_:
            warnings.warn(f"FastICA did not converge in {ica.max_iter} iterations (K={k})", RuntimeWarning,
                          stacklevel=2)
        w = ica.components_                                    # s = W (x - mean)
        s = s - (-w @ ica.mean_)                               # shift so the neutral (x = 0) gives s = 0
        lo, hi = np.quantile(s, 1 - self.strong_quantile, axis=0), np.quantile(s, self.strong_quantile, axis=0)
        sign = np.where(hi >= -lo, 1.0, -1.0)                  # the larger excursion from neutral is positive
        scale = np.maximum(np.where(sign > 0, hi, -lo), 1e-12)
        self.unmixing_ = (sign / scale)[:, None] * w
        # order the actuations by how much signal they carry (largest first)
        s = s * (sign / scale)
        strength = np.linalg.norm(np.linalg.pinv(self.unmixing_), axis=0)
        self.unmixing_ = self.unmixing_[np.argsort(-strength)]
        self.n_signals_ = n_classes
        return self

    def signals(self, disp: np.ndarray) -> np.ndarray:
        """Actuation signals (n_frames, n_classes), float64, of displacements (n_frames, n_markers, 3)."""
        self._check_fitted()
        return actuation_signals(disp, self.axes_, self.axis_marker_, self.handover_power)

    def transform(self, disp: np.ndarray) -> np.ndarray:
        """Actuations s (n_frames, K), float64, of displacements (n_frames, n_markers, 3), float, units."""
        return self.signals(disp) @ self.unmixing_.T

    def _check_fitted(self):
        if not hasattr(self, "unmixing_"):
            raise RuntimeError("ActuationModel is not fitted; call fit(disp) first")


def k_report(disp: np.ndarray, signals: np.ndarray, ks: Sequence[int] = (1, 2, 4, 8, 13, 20, 30)) -> list[dict]:
    """Held-in marker reconstruction error versus K, actuation signals against plain PCA.

    FastICA rotates the whitened K-dimensional principal subspace of the
    signals, so any linear model of the markers from K ICA actuations equals
    one from the K principal components of the signals: the ICA column is
    computed that way (FastICA is not re-run per K). The PCA column is the
    best any K-dimensional linear model of the marker displacements can do.

    disp : ndarray of shape (n_frames, n_markers, 3), float, units (complete frames only)
    signals : ndarray of shape (n_frames, n_classes), float
    Returns list of {"k", "ica_rms", "pca_rms"} (RMS marker error, units) for the feasible K.
    """
    y = disp.reshape(len(disp), -1)
    y = y - y.mean(axis=0)
    xc = signals - signals.mean(axis=0)
    _, _, vx = np.linalg.svd(xc, full_matrices=False)
    _, sy, _ = np.linalg.svd(y, full_matrices=False)
    n_markers = disp.shape[1]
    total = float(np.sum(sy ** 2))
    rows = []
    for k in ks:
        if k > min(vx.shape[0], len(sy)):
            continue
        z = xc @ vx[:k].T
        coef, *_ = np.linalg.lstsq(z, y, rcond=None)
        ica = float(np.sqrt(np.sum((y - z @ coef) ** 2) / (len(y) * n_markers)))
        pca = float(np.sqrt(max(total - float(np.sum(sy[:k] ** 2)), 0.0) / (len(y) * n_markers)))
        rows.append({"k": int(k), "ica_rms": ica, "pca_rms": pca})
    return rows
