"""A synthetic marker take with known actuations, for tests and benchmarks.

K independent one-sided actuations s_k(t) in [0, 1] (smooth bumps at random
times) each move a region of markers along its own direction field with a
nonlinear (cubic) magnitude; rigid head motion, noise and occlusions are
added on top. The truth is returned with the capture, so training can be
checked against it (recovery up to permutation, sign and scale).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.geometry import euler_to_quat, quat_to_matrix

from facepuppet.offline.io.capture import Capture, fill_gaps


def synthetic_actuations(n_frames: int, k: int, rng: np.random.Generator, rate: float = 60.0) -> np.ndarray:
    """Independent sparse bump trains: ndarray of shape (n_frames, k), float64, in [0, 1]."""
    s = np.zeros((n_frames, k))
    t = np.arange(n_frames)
    for j in range(k):
        n_events = max(2, int(n_frames / rate / 4.0))
        for centre in rng.uniform(0, n_frames, n_events):
            width = rng.uniform(0.25, 0.8) * rate
            bump = np.clip(1.0 - np.abs(t - centre) / width, 0.0, None)
            s[:, j] = np.maximum(s[:, j], rng.uniform(0.3, 1.0) * (0.5 - 0.5 * np.cos(np.pi * bump)))
    return s


def synthetic_capture(n_frames: int = 3500, n_markers: int = 68, k: int = 13, noise: float = 0.005,
                      occlusion_gaps: int = 20, head_motion: bool = True, seed: int = 0) -> tuple[Capture, dict]:
    """A take in cm with known actuations.

    Parameters
    ----------
    n_frames, n_markers, k : sizes (the paper's take: 3,500 frames, 68 markers, K = 13)
    noise : float, marker noise standard deviation, cm
    occlusion_gaps : int, number of random occlusion gaps (most short, one long)
    head_motion : bool, add a rigid head motion (a few degrees, about 1 cm)
    seed : int

    Returns
    -------
    capture : Capture (n_frames, n_markers, 3), cm, 60 Hz; markers named ``M00``...,
        the first four (``M00``-``M03``, forehead) never deform
    truth : dict with "s" (n_frames, k) actuations, "neutral" (n_markers, 3),
        "coef" (3, k, n_markers, 3) cubic coefficients, "head_markers" (4,) int,
        "clean" (n_frames, n_markers, 3) head-coordinate markers without noise
    """
    rng = np.random.default_rng(seed)
    if n_markers < 8 or k < 1:
        raise ValueError(f"synthetic_capture: need n_markers >= 8 and k >= 1, got {n_markers}, {k}")
    # neutral: points on the front of an ellipsoid (a face ~14 cm wide, 20 cm tall)
    u = rng.uniform(-0.9, 0.9, n_markers)
    v = rng.uniform(-1.0, 0.8, n_markers)
    u[:4], v[:4] = [-0.5, 0.5, 0.0, 0.0], [0.9, 0.9, 1.0, 0.45]  # forehead + nose bridge, not collinear
    neutral = np.c_[7.0 * np.sin(u), 10.0 * v, 6.0 * np.cos(u) * np.sqrt(np.clip(1 - 0.5 * v * v, 0.1, 1))]
    coef = np.zeros((3, k, n_markers, 3))
    for j in range(k):
        centre = neutral[rng.integers(4, n_markers)]
        reach = rng.uniform(1.5, 3.0)
        fall = np.exp(-np.sum((neutral - centre) ** 2, axis=1) / (2 * reach ** 2))
        fall[:4] = 0.0                                           # head markers stay rigid
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        swirl = np.cross(direction, neutral - centre) * 0.05
        field = fall[:, None] * (direction + swirl)
        amp = rng.uniform(0.6, 1.5)                              # cm at s = 1
        c, b, a = amp * 0.7, amp * 0.45, -amp * 0.15             # nonlinear, monotone on [0, 1]
        coef[0, j], coef[1, j], coef[2, j] = a * field, b * field, c * field
    s = synthetic_actuations(n_frames, k, rng)
    phi = np.concatenate([s ** 3, s ** 2, s], axis=1)
    clean = neutral + (phi @ coef.reshape(3 * k, -1)).reshape(n_frames, n_markers, 3)
    markers = clean + rng.normal(scale=noise, size=clean.shape)
    if head_motion:
        t = np.arange(n_frames) / 60.0
        yaw, pitch, roll = (np.radians(3.0) * np.sin(0.4 * t), np.radians(2.0) * np.sin(0.3 * t + 1),
                            np.radians(1.5) * np.sin(0.2 * t + 2))
        rot = np.stack([quat_to_matrix(euler_to_quat(a, b, c)) for a, b, c in zip(yaw, pitch, roll)])
        shift = np.c_[0.5 * np.sin(0.25 * t), 0.3 * np.sin(0.35 * t), 0.4 * np.sin(0.15 * t)]
        markers = markers @ np.swapaxes(rot, 1, 2) + shift[:, None, :]
    for g in range(occlusion_gaps):
        j = int(rng.integers(4, n_markers))
        length = 40 if g == 0 else int(rng.integers(1, 6))
        start = int(rng.integers(1, n_frames - length - 1))
        markers[start:start + length, j] = np.nan
    capture = Capture(markers.astype(np.float32), tuple(f"M{i:02d}" for i in range(n_markers)), 60.0, "cm",
                      "synthetic")
    filled, gaps, n_filled = fill_gaps(capture.markers, capture.names)
    capture = Capture(filled, capture.names, 60.0, "cm", "synthetic", tuple(gaps), n_filled)
    return capture, {"s": s, "neutral": neutral, "coef": coef, "head_markers": np.arange(4), "clean": clean}
