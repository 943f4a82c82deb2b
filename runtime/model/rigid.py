"""Least-squares rigid alignment of point sets (Kabsch), batched over frames.

Used offline to stabilise a whole take and at runtime to bring one live
marker frame into the actor's head coordinates.
"""

from __future__ import annotations

import numpy as np


def kabsch(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and translations that move ``q`` onto ``p`` in the least-squares sense.

    Parameters
    ----------
    p : ndarray of shape (..., h, 3), float, target points (h >= 3)
    q : ndarray of shape (..., h, 3), float, points to move

    Returns
    -------
    rotation : ndarray of shape (..., 3, 3), float64, proper rotations (det +1)
    translation : ndarray of shape (..., 3), float64, with p ≈ q @ R.T + t
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    pc, qc = p.mean(axis=-2), q.mean(axis=-2)
    h = np.swapaxes(q - qc[..., None, :], -1, -2) @ (p - pc[..., None, :])   # cross-covariance
    u, _, vt = np.linalg.svd(h)
    v, ut = np.swapaxes(vt, -1, -2), np.swapaxes(u, -1, -2)
    fix = np.ones(h.shape[:-2] + (3,))
    fix[..., 2] = np.sign(np.linalg.det(v @ ut))               # no reflections
    r = v @ (fix[..., :, None] * ut)
    t = pc - (r @ qc[..., :, None])[..., 0]
    return r, t
