"""How well each proposed landmark fits its neighbours, by the source's layout: the doubts of a poor local fit.

The cloning carries the source's motion of each control point to its target
point, so it can be trusted where the target's points are laid out as the
source's are, up to the face's own proportions. That is measured here, on
the front view (x, y of the face frame; a decal face is flat where the
source's face is round, so depth says nothing of the layout):

1. the whole face's proportions: the affine map of the source's points onto
   the target's (a wider face, a longer jaw) by least squares;
2. for each point, its ``NEIGHBOURS`` nearest points in the source (after
   that map), their best similarity (turn, scale, shift) onto the target's,
   and where it puts the point: the **residual** is the distance from there
   to the proposed point over the neighbours' mean distance to it;
3. the worst point above ``POOR`` is doubtful, taken out of every fit, and
   step 1–2 run again, until none is left above it (at most a third of the
   points): a single misplaced point spoils its neighbours' fits too, and
   is the one that stands out most.

A feature drawn at other proportions than the source's (an anime eye four
times as tall as ICT's, a mouth drawn as a line) shows as poor fits too: its
points are not where the source's layout, scaled, puts them, and the source's
motion at the source's proportions is not what the feature should do.

The threshold was set on the ICT head (its true points: every residual 0;
stylised by ``bench kpls``'s warp, big eyes and a long jaw: at most 0.18;
points of it moved by hand: a lid onto the brow 1.4, a mouth corner a third
of the mouth inwards 0.9, an eye corner 0.3 inner-eye distances down 0.67)
and checked on the MediaPipe face with its landmarks of known meaning (at
most 0.49; the proposal's lower inner lip, 0.32 inner-eye distances from
MediaPipe's, 1.43).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

NEIGHBOURS = 6
POOR = 0.6  # a residual above this (of the neighbours' mean distance) is a poor local fit
MAX_SHARE = 1 / 3  # at most this share of the points is found doubtful by their fit (the rest must hold)


def _affine(src: np.ndarray, tgt: np.ndarray) -> np.ndarray:
    """(3, 2) least-squares affine map: [src, 1] @ a ≈ tgt."""
    a = np.column_stack([src, np.ones(len(src))])
    return np.linalg.lstsq(a, tgt, rcond=None)[0]


def _similarity(src: np.ndarray, tgt: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(scale, rotation (2, 2), source mean, target mean) of the best 2D similarity src -> tgt (Umeyama)."""
    ms, mt = src.mean(0), tgt.mean(0)
    a, b = src - ms, tgt - mt
    u, sig, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = u @ np.diag([1.0, d]) @ vt
    var = float((a**2).sum())
    scale = float((sig * [1.0, d]).sum()) / var if var > 0 else 0.0
    return scale, rot, ms, mt


def residuals(source: np.ndarray, target: np.ndarray, left_out: np.ndarray | None = None) -> tuple[np.ndarray,
                                                                                                     np.ndarray]:
    """Each point's local-fit residual (n,) and its neighbours (n, NEIGHBOURS) (indices), from points (n, 2)
    ``source`` and ``target`` (see the module doc); ``left_out`` (bool (n,)) points take no part in any fit
    (their own residual is still measured)."""
    s, t = np.asarray(source, np.float64), np.asarray(target, np.float64)
    n = len(s)
    keep = np.ones(n, bool) if left_out is None else ~np.asarray(left_out, bool)
    mapped = np.column_stack([s, np.ones(n)]) @ _affine(s[keep], t[keep])
    k = min(NEIGHBOURS, int(keep.sum()) - 1)
    out = np.zeros(n)
    near = np.zeros((n, max(k, 0)), np.int64)
    if k < 3:
        return out, near
    for i in range(n):
        others = np.flatnonzero(keep & (np.arange(n) != i))
        d = np.linalg.norm(mapped[others] - mapped[i], axis=1)
        nb = others[np.argsort(d)[:k]]
        near[i] = nb
        scale, rot, ms, mt = _similarity(mapped[nb], t[nb])
        predicted = scale * (mapped[i] - ms) @ rot.T + mt
        spread = scale * float(np.linalg.norm(mapped[nb] - mapped[i], axis=1).mean())
        out[i] = float(np.linalg.norm(predicted - t[i])) / spread if spread > 0 else np.inf
    return out, near


def poor_fits(source: np.ndarray, target: np.ndarray, names: Sequence[str],
              poor: float = POOR) -> list[dict]:
    """Doubts {"points": [name], "why": text, "residual": r} for the points (front-view (n, 2) ``source`` and
    ``target``, in ``names``' order) whose local fit is poor, worst first (see the module doc)."""
    names = tuple(names)
    n = len(names)
    out_mask = np.zeros(n, bool)
    found = []
    while out_mask.sum() < MAX_SHARE * n:
        r, near = residuals(source, target, out_mask)
        r[out_mask] = -np.inf
        worst = int(np.argmax(r))
        if not r[worst] > poor:
            break
        out_mask[worst] = True
        found.append((worst, float(r[worst]), near[worst]))
    return [{"points": [names[i]], "residual": round(res, 3),
             "why": f"poor local fit: {res:.2f} of its neighbours' spacing from where the source's layout of "
                    f"{', '.join(names[j] for j in nb[:4])}… puts it (> {poor}): another place or proportions "
                    "than the source's"} for i, res, nb in found]
