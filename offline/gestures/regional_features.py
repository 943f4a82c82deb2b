"""Regional residual features (Ju & Lee 2008, §4.2) and the head track.

The residual left after the blend weights (x(t) - c(t)·B, :mod:`.blend_weights`)
is split into non-overlapping groups by channel name: brows, eyes, lips and
the rest. The lips P(t) are kept apart, as speech drives them; the others are
the stochastic features D_j(t). The head pose is its own track: rotation
(yaw, pitch, roll, radians) and translation (source units) of the rigid
motion of a marker take's stable markers, relative to its first frame.

Symbols: P(t) -> group ``lips``, D_j(t) -> groups ``brows``, ``eyes``,
``rest``; head track -> ``head_track`` columns ``HEAD_FEATURES``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.gestures.layer import HEAD_FEATURES
from facepuppet.runtime.mapping.channels import gesture_group

REGIONS = ("brows", "eyes", "lips", "rest")
# markers that move rigidly with the skull in the AnimFace takes (data README: forehead + nose top)
STABLE_MARKERS = ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")


def split_regions(names: Sequence[str]) -> dict[str, np.ndarray]:
    """Column indices of each region, {region: ndarray of int64}; every column in exactly one."""
    regions = [gesture_group(n) for n in names]
    return {r: np.array([i for i, g in enumerate(regions) if g == r], np.int64) for r in REGIONS}


def head_track(markers: np.ndarray, names: Sequence[str], stable: Sequence[str] = STABLE_MARKERS) -> np.ndarray:
    """Head pose per frame from the rigid motion of the stable markers.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, source units; +y up, +z forward
    names : sequence of n_markers str
    stable : names of markers fixed to the skull

    Returns
    -------
    track : ndarray of shape (n_frames, 6), float64: yaw, pitch, roll (radians; about +y, +x, +z),
        then the translation of the stable markers' centroid (source units), relative to frame 0
    """
    markers = np.asarray(markers, np.float64)
    if markers.ndim != 3 or markers.shape[2] != 3:
        raise ValueError(f"markers: expected shape (n_frames, n_markers, 3), got {markers.shape}")
    missing = [m for m in stable if m not in list(names)]
    if missing:
        raise InputFileError(f"markers: expected stable markers {list(stable)}, missing {missing}")
    idx = [list(names).index(m) for m in stable]
    pts = markers[:, idx]
    if not np.isfinite(pts).all():
        raise InputFileError("markers: the stable markers have NaN samples; fill or drop those frames first")
    ref = pts[0] - pts[0].mean(0)
    out = np.zeros((len(pts), 6))
    for t, p in enumerate(pts):
        centre = p.mean(0)
        rot, _ = Rotation.align_vectors(p - centre, ref)  # rigid fit (Kabsch): rot · ref ≈ p
        # R = Ry(yaw) · Rx(pitch) · Rz(roll), the runtime's euler_to_quat order
        yaw, pitch, roll = rot.as_euler("YXZ")
        out[t, :3] = yaw, pitch, roll
        out[t, 3:] = centre - pts[0].mean(0)
    assert out.shape[1] == len(HEAD_FEATURES)
    return out
