"""Head stabilisation: remove the rigid head motion from a marker take.

Rigid head markers are given by name or found (``head_choice``: rigid, spanning
the face, named for the skull; refused as ambiguous when the take cannot tell).
Each frame is aligned to the reference
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

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.rigid import kabsch

from facepuppet.offline.actuation.head_choice import (
    RIGID_WARN_MM,
    AmbiguousHead,
    HeadChoice,
    choose_head_markers,
    describe_given,
    rigidity_mm,
)

__all__ = ["RIGID_WARN_MM", "AmbiguousHead", "HeadChoice", "Stabilised", "choose_head_markers", "find_head_markers",
           "kabsch", "rigidity_mm", "stabilise"]

DEFAULT_N_HEAD = 4
#: millimetres per capture unit
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
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
    choice : HeadChoice or None, how the head markers were chosen (found, found by name, given) and their
        rigidity; None only for a :class:`Stabilised` built by hand
    mm_per_unit : float, millimetres per capture unit (the summary reports the residual in mm)
    """

    markers: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    head_markers: tuple[int, ...]
    head_fixed: bool
    rms_residual: float
    max_angle_deg: float
    bad_frames: tuple[int, ...] = ()
    choice: HeadChoice | None = None
    mm_per_unit: float = 1.0

    def summary(self) -> str:
        if self.head_fixed:
            return f"capture is already head-fixed (head markers move < {HEAD_FIXED_TOLERANCE:.0e} of their spread)"
        return (f"head motion removed: up to {self.max_angle_deg:.2f} deg, head-marker RMS residual "
                f"{self.rms_residual * self.mm_per_unit:.3f} mm" + (f", {len(self.bad_frames)} frames without a pose"
                                                    if self.bad_frames else ""))


def find_head_markers(markers: np.ndarray, n: int = DEFAULT_N_HEAD) -> tuple[int, ...]:
    """The ``n`` markers of :func:`choose_head_markers` (indices, sorted)."""
    return choose_head_markers(markers, n).markers


def stabilise(markers: np.ndarray, names: Sequence[str], head_markers: Sequence[str | int] | None = None,
              reference_frame: int = 0,
              n_head: int = DEFAULT_N_HEAD, mm_per_unit: float = 1.0) -> Stabilised:
    """Express a take in head coordinates.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, capture units, NaN = occluded
    names : sequence of n_markers str
    head_markers : sequence of str (names) or int (indices), or None to find them (by the names and the
        motion: :func:`~facepuppet.offline.actuation.head_choice.choose_head_markers`, which refuses with
        :class:`~facepuppet.offline.actuation.head_choice.AmbiguousHead` when the take cannot tell)
    reference_frame : int, the frame whose head pose defines head coordinates
    n_head : int, how many head markers to find when none are given
    mm_per_unit : float, millimetres per capture unit (the set's rigidity is reported in mm)
    """
    m = np.asarray(markers, dtype=np.float64)
    names = list(names)
    if head_markers is None:
        choice = choose_head_markers(m, n_head, mm_per_unit, names)
        idx = choice.markers
    else:
        idx = []
        for h in head_markers:
            if isinstance(h, str):
                if h not in names:
                    raise UsageError(f"head markers: no marker named {h!r}; known: {', '.join(names[:8])}...")
                idx.append(names.index(h))
            else:
                idx.append(int(h))
        idx = tuple(sorted(set(idx)))
        if len(idx) < 3:
            raise UsageError(f"head markers: need at least 3 distinct markers, got {len(idx)}")
        choice = describe_given(m, idx, mm_per_unit)
    if not 0 <= reference_frame < len(m):
        raise ValueError(f"reference_frame: expected 0..{len(m) - 1}, got {reference_frame}")
    head = m[:, idx]
    ref = head[reference_frame]
    if np.isnan(ref).any():
        raise UsageError(f"reference_frame {reference_frame}: a head marker is occluded there; choose another frame")
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
                          tuple(idx), True, rms, float(angles.max()), tuple(bad), choice, mm_per_unit)
    return Stabilised(out.astype(np.float32), rot, trans, tuple(idx), False, rms, float(angles.max()), tuple(bad),
                      choice, mm_per_unit)
