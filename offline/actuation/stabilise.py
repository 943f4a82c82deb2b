"""Head stabilisation: remove the rigid head motion from a marker take.

Rigid head markers are given by name or found as the set whose mutual
distances change least over the take. Each frame is aligned to the reference
frame by Kabsch (least-squares rotation + translation of the head markers),
giving the markers in head coordinates and a head pose track. A take whose
head markers already stand still is reported as head-fixed and left as is.

Symbols: reference head markers P (h, 3), frame head markers Q (h, 3);
rotation R and translation t with R Q + t ≈ P (frame -> head coordinates).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.rigid import kabsch

__all__ = ["Stabilised", "kabsch", "find_head_markers", "stabilise"]

DEFAULT_N_HEAD = 4
# A take is "already head-fixed" when the head markers move less than this
# fraction of their spread (RMS over the take) -- 0.1 mm on a 10 cm face.
HEAD_FIXED_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Stabilised:
    """A take in head coordinates.

    Attributes
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float32, capture units, head coordinates
    rotation : ndarray of shape (n_frames, 3, 3), float64, capture frame -> head frame
    translation : ndarray of shape (n_frames, 3), float64, capture units
    head_markers : tuple of int, marker indices used as the rigid set
    head_fixed : bool, the take was already head-fixed (nothing removed)
    rms_residual : float, RMS distance of the head markers to the reference after alignment, units
    max_angle_deg : float, largest head rotation relative to the reference frame, degrees
    bad_frames : tuple of int, frames with fewer than 3 visible head markers (pose copied from a neighbour)
    """

    markers: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    head_markers: tuple[int, ...]
    head_fixed: bool
    rms_residual: float
    max_angle_deg: float
    bad_frames: tuple[int, ...] = ()

    def summary(self) -> str:
        if self.head_fixed:
            return f"capture is already head-fixed (head markers move < {HEAD_FIXED_TOLERANCE:.0e} of their spread)"
        return (f"head motion removed: up to {self.max_angle_deg:.2f} deg, head-marker RMS residual "
                f"{self.rms_residual:.4f} units" + (f", {len(self.bad_frames)} frames without a pose"
                                                    if self.bad_frames else ""))


def find_head_markers(markers: np.ndarray, n: int = DEFAULT_N_HEAD) -> tuple[int, ...]:
    """The ``n`` markers whose mutual distances vary least over the take.

    Greedy: start from the pair with the steadiest distance, then add the
    marker with the smallest mean distance deviation to those already chosen.
    """
    m = np.asarray(markers, dtype=np.float64)
    n_markers = m.shape[1]
    if n_markers < 3 or n < 3:
        raise ValueError(f"head markers: need at least 3 markers and n >= 3, got {n_markers} markers, n={n}")
    n = min(n, n_markers)
    dist = np.linalg.norm(m[:, :, None, :] - m[:, None, :, :], axis=-1)
    spread = np.nanstd(dist, axis=0)
    spread[np.isnan(spread)] = np.inf
    np.fill_diagonal(spread, np.inf)
    i, j = np.unravel_index(np.argmin(spread), spread.shape)
    chosen = [int(i), int(j)]
    while len(chosen) < n:
        score = spread[:, chosen].mean(axis=1)
        score[chosen] = np.inf
        chosen.append(int(np.argmin(score)))
    return tuple(sorted(chosen))


def stabilise(markers: np.ndarray, names: Sequence[str], head_markers: Sequence[str | int] | None = None,
              reference_frame: int = 0,
              n_head: int = DEFAULT_N_HEAD) -> Stabilised:
    """Express a take in head coordinates.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, capture units, NaN = occluded
    names : sequence of n_markers str
    head_markers : sequence of str (names) or int (indices), or None to find them
    reference_frame : int, the frame whose head pose defines head coordinates
    n_head : int, how many head markers to find when none are given
    """
    m = np.asarray(markers, dtype=np.float64)
    names = list(names)
    if head_markers is None:
        idx = find_head_markers(m, n_head)
    else:
        idx = []
        for h in head_markers:
            if isinstance(h, str):
                if h not in names:
                    raise ValueError(f"head markers: no marker named {h!r}; known: {', '.join(names[:8])}...")
                idx.append(names.index(h))
            else:
                idx.append(int(h))
        idx = tuple(sorted(set(idx)))
        if len(idx) < 3:
            raise ValueError(f"head markers: need at least 3 distinct markers, got {len(idx)}")
    if not 0 <= reference_frame < len(m):
        raise ValueError(f"reference_frame: expected 0..{len(m) - 1}, got {reference_frame}")
    head = m[:, idx]
    ref = head[reference_frame]
    if np.isnan(ref).any():
        raise ValueError(f"reference_frame {reference_frame}: a head marker is occluded there; choose another frame")
    visible = ~np.isnan(head).any(axis=2)
    n_frames = len(m)
    rot = np.tile(np.eye(3), (n_frames, 1, 1))
    trans = np.zeros((n_frames, 3))
    full = visible.all(axis=1)
    if full.any():
        rot[full], trans[full] = kabsch(np.broadcast_to(ref, head[full].shape), head[full])
    bad = []
    for f in np.flatnonzero(~full):
        v = visible[f]
        if v.sum() >= 3:
            rot[f], trans[f] = kabsch(ref[v], head[f, v])
        else:
            bad.append(int(f))
    ok = np.setdiff1d(np.arange(n_frames), bad)
    if bad and len(ok):
        nearest = ok[np.clip(np.searchsorted(ok, bad), 0, len(ok) - 1)]
        rot[bad], trans[bad] = rot[nearest], trans[nearest]
    spread = float(np.sqrt(np.mean(np.sum((ref - ref.mean(axis=0)) ** 2, axis=1))))
    angles = np.degrees(np.arccos(np.clip((np.trace(rot, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    out = m @ np.swapaxes(rot, 1, 2) + trans[:, None, :]
    aligned = out[:, idx]
    # the motion the rigid fit explains: how far alignment moves the head markers
    explained = float(np.sqrt(np.nanmean(np.sum((aligned - head) ** 2, axis=2))))
    rms = float(np.sqrt(np.nanmean(np.sum((aligned - ref) ** 2, axis=2))))
    if explained < HEAD_FIXED_TOLERANCE * spread:
        return Stabilised(m.astype(np.float32), np.tile(np.eye(3), (n_frames, 1, 1)), np.zeros((n_frames, 3)),
                          tuple(idx), True, rms, float(angles.max()), tuple(bad))
    return Stabilised(out.astype(np.float32), rot, trans, tuple(idx), False, rms, float(angles.max()), tuple(bad))
