"""Which markers are the skull: the automatic choice of head markers, and the report on a given set.

Rigidity alone cannot tell the skull: a region that holds still in a take (brows that never lift, a jaw held
closed) is as rigid as bone, and a few markers can keep their mutual distances by chance while they move.
So a head set must also span the face (forehead to nose bridge: a brow cluster a few centimetres wide
turns with any noise on it), names that say skull (forehead, temple, nose bridge, head band) are taken as
evidence, and where two sets that share no frame are both rigid and spanning but turn differently, nothing
in one take says which one is the skull: the choice refuses, names both, and asks for ``--head-markers``.

Symbols: distance SD matrix ``spread`` (n_markers, n_markers), mm; a set's *span* is the RMS distance of its
markers from the axis about which it turns least determinably (the square root of the smallest principal
moment per marker, mm), as a fraction of the whole layout's.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.rigid import kabsch

__all__ = ["AmbiguousHead", "HeadChoice", "RIGID_WARN_MM", "choose_head_markers", "describe_given",
           "rigidity_mm", "skull_named", "span_fraction"]

#: a head-marker set whose mutual distances vary more than this (SD, mm) is not rigid enough: warn
RIGID_WARN_MM = 1.0
#: a head set spans at least this fraction of the layout (see the module docstring): the AnimFace skull set
#: (forehead + nose bridge) spans 0.73 of its layout, a four-marker brow cluster 0.12-0.30
SPAN_FRACTION = 0.5
#: two rigid sets whose head frames turn apart by more than this over the take are rivals, degrees
AGREE_DEG = 0.5
#: a rival is at most this many times less rigid than the pick: four markers that deform in a way that keeps
#: their distances (a "rigid" set by chance) turn with their deformation. On the synthetic take (head set 0.07
#: mm) such sets reach 0.28-0.50 mm (4-7 times) and turn 2-5 deg apart; a still brow or jaw on the AnimFace jaw
#: take is 0.16-0.20 mm against its skull's 0.30-0.35 (1.5-2.2 times), a real rival
RIVAL_RATIO = 3.0
#: sets sharing this many markers share a frame; fewer (two share an axis) can turn apart as rivals
MIN_SHARED = 3
#: compact lower-case name fragments that say "on the skull"
SKULL_WORDS = ("forehead", "temple", "nosetop", "nosebridge", "bridge", "nasion", "glabella", "skull",
               "headband", "crown")
#: whole compact names that say "on the skull": Vicon's head markers (LFHD, RBHD...), Head, Head1, HeadTop
SKULL_NAME = re.compile(r"([lr][fb]hd|head\d*|head(top|front|back|left|right|l|r)\d*)")
#: at most this many name-evidence markers are searched for a rigid subset (2^8 subsets)
MAX_NAMED_SEARCH = 8


@dataclass(frozen=True)
class HeadChoice:
    """A head-marker set and the evidence for it.

    Attributes
    ----------
    markers : tuple of int, the marker indices, sorted
    rigidity_mm : float, the largest SD over the take of a distance between two of them, mm
    span : float, the set's span as a fraction of the layout's (see the module docstring)
    rigid : bool, ``rigidity_mm`` <= :data:`RIGID_WARN_MM`
    how : str, "found" (rigid and spanning, no rival), "named" (found by the markers' names) or "given"
    rivals : tuple of (markers, degrees): for a set found by name, the rigid spanning set, more rigid than it
        and sharing fewer than :data:`MIN_SHARED` markers with it, that turns furthest apart from it (by more
        than :data:`AGREE_DEG`); the names decided between them
    """

    markers: tuple[int, ...]
    rigidity_mm: float
    span: float
    rigid: bool
    how: str = "found"
    rivals: tuple[tuple[tuple[int, ...], float], ...] = field(default=())

    def describe(self, names: Sequence[str]) -> str:
        """One line: the set, how it was chosen, its rigidity and span, and what is doubtful about it."""
        label = {"found": "found", "named": "found by name", "given": "given"}[self.how]
        text = (f"head markers ({label}): {_names(self.markers, names)}; rigidity: distance SD "
                f"up to {self.rigidity_mm:.2f} mm over the take")
        if not self.rigid:
            text += (f"; warning: not rigid (over {RIGID_WARN_MM:g} mm): head motion and expression mix; "
                     "name rigid markers with --head-markers")
        if self.span < SPAN_FRACTION:
            text += (f"; warning: they span {self.span:.2f} of the face (under {SPAN_FRACTION:g}): the head's "
                     "rotation is poorly determined from them")
        for other, apart in self.rivals:
            text += (f"; note: {_names(other, names)} are rigid too and turn up to {apart:.2f} deg apart from "
                     "these; if they are the skull, name them with --head-markers")
        return text


class AmbiguousHead(UsageError):
    """Two disjoint rigid spanning sets turn differently: which is the skull is the user's call.

    Attributes
    ----------
    candidates : tuple of tuple of int, the rival sets (marker indices), the most rigid first
    """

    def __init__(self, message: str, candidates: tuple[tuple[int, ...], ...]) -> None:
        super().__init__(message)
        self.candidates = candidates


def _names(head: Sequence[int], names: Sequence[str]) -> str:
    return ", ".join(names[i] for i in head)


def skull_named(names: Sequence[str]) -> tuple[int, ...]:
    """Indices of the markers whose names say they sit on the skull (:data:`SKULL_WORDS`, :data:`SKULL_NAME`).

    ``NoseHead`` (the nose tip in the AnimFace layout) is not a head marker: a name counts when it *is* a head
    word (``Head_L``, ``RFHD``), not when it merely contains one.
    """
    out = []
    for i, name in enumerate(names):
        compact = re.sub(r"[^a-z0-9]", "", name.lower())
        if any(w in compact for w in SKULL_WORDS) or SKULL_NAME.fullmatch(compact):
            out.append(i)
    return tuple(out)


def _axis_rms(points: np.ndarray) -> float:
    """RMS distance of ``points`` (h, 3) from the axis through their centre they lie closest to."""
    p = points - points.mean(axis=0)
    s = p.T @ p
    inertia = np.trace(s) * np.eye(3) - s
    return float(np.sqrt(max(np.linalg.eigvalsh(inertia)[0], 0.0) / len(p)))


def span_fraction(markers: np.ndarray, head: Sequence[int]) -> float:
    """The span of ``head`` over the layout's, both from the markers' median positions over the take.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, capture units, NaN = occluded
    head : sequence of int, marker indices
    """
    rest = np.nanmedian(np.asarray(markers, dtype=np.float64), axis=0)
    seen = np.isfinite(rest).all(axis=1)
    layout = _axis_rms(rest[seen])
    h = rest[list(head)]
    h = h[np.isfinite(h).all(axis=1)]
    if layout <= 0 or len(h) < 3:
        return 0.0
    return _axis_rms(h) / layout


def rigidity_mm(markers: np.ndarray, head: Sequence[int], mm_per_unit: float = 1.0) -> float:
    """The largest SD over the take of a distance between two of the ``head`` markers, mm (0 for one marker)."""
    h = np.asarray(markers, dtype=np.float64)[:, list(head)]
    dist = np.linalg.norm(h[:, :, None, :] - h[:, None, :, :], axis=-1)
    sd = np.nanstd(dist, axis=0)
    return float(np.nanmax(sd) * mm_per_unit) if np.isfinite(sd).any() else float("nan")


def describe_given(markers: np.ndarray, head: Sequence[int], mm_per_unit: float = 1.0) -> HeadChoice:
    """The report on head markers the user named: rigidity and span, warned about as for a found set."""
    rigidity = rigidity_mm(markers, head, mm_per_unit)
    return HeadChoice(tuple(head), rigidity, span_fraction(markers, head), bool(rigidity <= RIGID_WARN_MM),
                      "given")


def _frames(m: np.ndarray, head: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame rotation into the set's frame-of-first-full-frame, and the mask of frames it is known in."""
    h = m[:, list(head)]
    full = ~np.isnan(h).any(axis=(1, 2))
    rot = np.tile(np.eye(3), (len(m), 1, 1))
    if full.any():
        ref = h[np.flatnonzero(full)[0]]
        rot[full] = kabsch(np.broadcast_to(ref, h[full].shape), h[full])[0]
    return rot, full


def _apart_deg(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    """The largest angle between two sets' head rotations (each relative to its own first frame), degrees.

    Both are referred to the first frame they share, so the answer does not depend on where either starts.
    """
    both = a[1] & b[1]
    if both.sum() < 2:
        return 0.0
    ra, rb = a[0][both], b[0][both]
    ra = ra[0].T @ ra          # frame f -> the shared first frame
    rb = rb[0].T @ rb
    diff = ra @ np.swapaxes(rb, 1, 2)
    cos = np.clip((np.trace(diff, axis1=1, axis2=2) - 1) / 2, -1, 1)
    return float(np.degrees(np.arccos(cos)).max())


def _grown_sets(spread: np.ndarray, n: int) -> set[tuple[int, ...]]:
    """From each marker, a set of ``n`` grown greedily by the marker whose distances to it vary least."""
    sets = set()
    for seed in range(len(spread)):
        chosen = [seed]
        while len(chosen) < n:
            score = spread[:, chosen].max(axis=1)
            score[chosen] = np.inf
            chosen.append(int(np.argmin(score)))
        sets.add(tuple(sorted(chosen)))
    return sets


def _named_choice(m: np.ndarray, named: tuple[int, ...], spread: np.ndarray) -> tuple[int, ...] | None:
    """The skull-named set, or its largest rigid spanning subset when it is not rigid as a whole; None when
    no subset of three or more spans the face."""
    whole = float(spread[np.ix_(named, named)].max())
    if whole <= RIGID_WARN_MM and span_fraction(m, named) >= SPAN_FRACTION:
        return named
    pool = named if len(named) <= MAX_NAMED_SEARCH else tuple(sorted(named, key=lambda i: spread[i, named].max())
                                                              )[:MAX_NAMED_SEARCH]
    best = None
    for size in range(len(pool), 2, -1):
        for sub in combinations(pool, size):
            if span_fraction(m, sub) < SPAN_FRACTION:
                continue
            r = float(spread[np.ix_(sub, sub)].max())
            if r <= RIGID_WARN_MM and (best is None or r < best[0]):
                best = (r, sub)
        if best is not None:
            return best[1]
    return named if span_fraction(m, named) >= SPAN_FRACTION else None


def choose_head_markers(markers: np.ndarray, n: int = 4, mm_per_unit: float = 1.0,
                        names: Sequence[str] | None = None) -> HeadChoice:
    """The skull's markers in a take, or :class:`AmbiguousHead` when the take cannot tell.

    1. Names: when at least three markers are named for the skull (:func:`skull_named`) and they span the
       face, they are the head (their most rigid spanning subset of three or more if the whole set is not
       rigid; the whole set, with the rigidity warning, if no subset is).
    2. Otherwise candidates are grown from each marker (:func:`_grown_sets`, ``n`` markers); those spanning
       :data:`SPAN_FRACTION` of the face and rigid to :data:`RIGID_WARN_MM` compete, and the most rigid wins
       unless another spanning one, at most :data:`RIVAL_RATIO` times less rigid and sharing fewer than
       :data:`MIN_SHARED` markers with it, turns more than :data:`AGREE_DEG` apart from it over the take:
       then the choice is ambiguous (:class:`AmbiguousHead`). With no rigid spanning candidate the most
       rigid spanning one (or the most rigid of all) is returned, and its report warns.

    Parameters
    ----------
    markers : ndarray of shape (n_frames, n_markers, 3), float, capture units, NaN = occluded
    n : int, the size of a grown candidate (at least 3)
    mm_per_unit : float, millimetres per capture unit
    names : sequence of n_markers str, or None (then only the motion can tell)
    """
    m = np.asarray(markers, dtype=np.float64)
    n_markers = m.shape[1]
    if n_markers < 3 or n < 3:
        raise ValueError(f"head markers: need at least 3 markers and n >= 3, got {n_markers} markers, n={n}")
    if names is not None and len(names) != n_markers:
        raise ValueError(f"head markers: {len(names)} names for {n_markers} markers")
    n = min(n, n_markers)
    dist = np.linalg.norm(m[:, :, None, :] - m[:, None, :, :], axis=-1)
    spread = np.nanstd(dist, axis=0) * mm_per_unit
    spread[np.isnan(spread)] = np.inf
    np.fill_diagonal(spread, 0.0)

    def rigidity(c: tuple[int, ...]) -> float:
        return float(spread[np.ix_(c, c)].max())

    candidates = sorted(_grown_sets(spread, n))
    span = {c: span_fraction(m, c) for c in candidates}
    spanning = [c for c in candidates if span[c] >= SPAN_FRACTION]
    rigid = sorted((c for c in spanning if rigidity(c) <= RIGID_WARN_MM), key=lambda c: (rigidity(c), -span[c]))
    named = skull_named(names) if names is not None else ()
    pick = _named_choice(m, named, spread) if len(named) >= 3 else None
    if pick is not None:
        frame = _frames(m, pick)
        rivals = []
        for c in rigid:
            # only a set more rigid than the named one is worth a note: names outweigh a less rigid set
            if len(set(c) & set(pick)) < MIN_SHARED and rigidity(c) <= rigidity(pick):
                apart = _apart_deg(frame, _frames(m, c))
                if apart > AGREE_DEG:
                    rivals.append((c, apart))
        rivals.sort(key=lambda r: -r[1])
        r = rigidity(pick)
        return HeadChoice(pick, r, span_fraction(m, pick), r <= RIGID_WARN_MM, "named", tuple(rivals[:1]))
    if not rigid:
        pool = spanning or candidates
        pick = min(pool, key=lambda c: (rigidity(c), -span[c]))
        return HeadChoice(pick, rigidity(pick), span[pick], rigidity(pick) <= RIGID_WARN_MM, "found")
    pick = rigid[0]
    frame = _frames(m, pick)
    rivals = [(c, _apart_deg(frame, _frames(m, c))) for c in spanning if c != pick
              if len(set(c) & set(pick)) < MIN_SHARED and rigidity(c) <= RIVAL_RATIO * rigidity(pick)]
    rivals = sorted((r for r in rivals if r[1] > AGREE_DEG), key=lambda r: -r[1])
    if rivals:
        other, apart = rivals[0]
        label = (lambda c: _names(c, names)) if names is not None else (lambda c: ", ".join(map(str, c)))
        raise AmbiguousHead(
            f"head markers: ambiguous: {label(pick)} (distance SD up to {rigidity(pick):.2f} mm) and "
            f"{label(other)} ({rigidity(other):.2f} mm) both span the face and hold their shape, but turn up to "
            f"{apart:.2f} deg apart over the take: a region that holds still is as rigid as the skull, and this "
            "take cannot tell which one is; name the skull's markers (forehead, nose bridge, head band) with "
            "--head-markers", (pick, other))
    return HeadChoice(pick, rigidity(pick), span[pick], True, "found")
