"""Checks of a proposal's layout that hold on every face, and the grouping of doubts by feature.

A face of any proportions keeps its features in order: on each side the
brow above the upper lid, the upper lid above the lower one, the lids
between the eye's corners and about as far apart for the eye's width as the
source's (within a factor ``EYE_SHAPE``: an anime eye is taller, but lids
six times as far apart are on the lashes or the brow, not the opening); the mouth's corners at the ends of its points,
the upper lip above the lower. A proposal breaking one of these is wrong
whatever the face looks like (the lid landmarks on the brow line, the mouth
corners inside the lips). The mouth's points must also span a mouth: its
points on one line or one spot (their height a small share of the source's,
against their width) leave the cloning nothing to tell the lips apart with, and
crowded into a small share of the source's mouth width (against the eyes'
distance, ``MOUTH_SPAN``) they may have missed the mouth.

On a decal face (features drawn on pieces, :mod:`.pieces`) the eye's points
must lie within the drawn eye's box and the mouth's on the drawn mouth
(:func:`decal_doubts`).

The points are compared on the front view (x, y of the face frame, x the
character's left).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

DECAL_MARGIN = 0.1  # a decal feature's points lie within its box grown by this share of its size
ORDER_SLACK = 0.02  # an ordering broken by less than this many inner-eye distances is a tie, not a fault
EYE_SHAPE = 3.0  # lids further apart (or closer) for the eye's width than this factor of the source's
MOUTH_SPAN = 0.4  # mouth points spanning under this share of the source's width (in inner-eye distances)
FLAT_MOUTH = 0.3  # mouth points whose height/width is under this share of the source's lie on a line
FEATURES = (  # (feature, name prefixes) for grouping doubts; the first match wins
    ("left eye", ("eye_inner_L", "eye_outer_L", "lid_upper_inner_L", "lid_upper_outer_L", "lid_lower_inner_L",
                  "lid_lower_outer_L")),
    ("right eye", ("eye_inner_R", "eye_outer_R", "lid_upper_inner_R", "lid_upper_outer_R", "lid_lower_inner_R",
                   "lid_lower_outer_R")),
    ("mouth", ("mouth_", "lip_")),
    ("brows", ("brow_",)),
    ("nose", ("nose_", "nostril_")),
    ("jaw", ("jaw_", "chin")),
    ("forehead and cheeks", ("forehead", "cheek")),
)


def feature_of(name: str) -> str:
    """The feature a control point belongs to (``FEATURES``), "other" for none."""
    return next((f for f, prefixes in FEATURES if name.startswith(prefixes)), "other")


def _y(p: dict, *names: str) -> float | None:
    got = [p[n][1] for n in names if n in p]
    return float(np.mean(got)) if got else None


def order_doubts(source: np.ndarray, target: np.ndarray, names: Sequence[str], es: float,
                 proportions: bool = True) -> list[dict]:
    """Doubts {"points", "why"} for the orderings of the module doc that ``target`` (front view (n, 2), in
    ``names``' order; ``es`` its inner-eye distance) breaks, and (``proportions``) for eyes and a mouth far from
    the ``source``'s (n, 2) proportions: not for features drawn on decals, whose points are placed by what is
    drawn and whose motion is scaled by it (:mod:`.landmark_field`, :mod:`.drawn_eyes`)."""
    names = tuple(names)
    p = {n: np.asarray(target[i], np.float64) for i, n in enumerate(names)}
    q = {n: np.asarray(source[i], np.float64) for i, n in enumerate(names)}
    tie = ORDER_SLACK * es
    out = []
    for side in ("L", "R"):
        upper = [f"lid_upper_{k}_{side}" for k in ("inner", "outer") if f"lid_upper_{k}_{side}" in p]
        lower = [f"lid_lower_{k}_{side}" for k in ("inner", "outer") if f"lid_lower_{k}_{side}" in p]
        brows = [f"brow_{k}_{side}" for k in ("inner", "mid", "outer") if f"brow_{k}_{side}" in p]
        brow, lid_up, lid_low = _y(p, *brows), _y(p, *upper), _y(p, *lower)
        if brow is not None and lid_up is not None and lid_up > brow - tie:
            out.append({"points": upper + brows, "why": f"the upper lid is not below the brow ({side} side: lid "
                                                        f"{(lid_up - brow) / es:+.2f} inner-eye distances from it)"})
        if lid_up is not None and lid_low is not None and lid_low > lid_up - tie:
            out.append({"points": upper + lower, "why": f"the upper lid is not above the lower one ({side} side)"})
        corners = [p.get(f"eye_inner_{side}"), p.get(f"eye_outer_{side}")]
        src_corners = [q.get(f"eye_inner_{side}"), q.get(f"eye_outer_{side}")]
        if proportions and all(c is not None for c in corners + src_corners) and lid_up is not None and \
                lid_low is not None:
            tall = (lid_up - lid_low) / max(abs(corners[1][0] - corners[0][0]), 1e-12)
            src_tall = ((_y(q, *upper) - _y(q, *lower)) / max(abs(src_corners[1][0] - src_corners[0][0]), 1e-12))
            if src_tall > 0 and not 1 / EYE_SHAPE < tall / src_tall < EYE_SHAPE:
                out.append({"points": upper + lower, "why": f"the lids are {tall / src_tall:.1f} times as far apart "
                                                            f"for the eye's width as the source's ({side} side): the "
                                                            "lid points are not on the eye's opening (on the "
                                                            "lashes or the brow?)"})
        if all(c is not None for c in corners):
            lo, hi = sorted((corners[0][0], corners[1][0]))
            margin = 0.15 * (hi - lo)
            off = [n for n in upper + lower if not lo - margin <= p[n][0] <= hi + margin]
            if off:
                out.append({"points": off, "why": f"lid points outside the eye's corners across the eye ({side} "
                                                  "side): the lids must lie on the eye opening"})
    mouth = [n for n in names if feature_of(n) == "mouth"]
    if "mouth_corner_L" in p and "mouth_corner_R" in p and len(mouth) > 2:
        xs = np.array([p[n][0] for n in mouth])
        left, right = p["mouth_corner_L"][0], p["mouth_corner_R"][0]
        width = left - right
        inside = width > 0 and xs.max() <= left + 0.05 * width and xs.min() >= right - 0.05 * width
        if not inside:
            out.append({"points": ["mouth_corner_L", "mouth_corner_R"],
                        "why": "the mouth corners are not at the ends of the mouth's points"})
        span = float(np.ptp(xs)) / es
        src_es = float(np.linalg.norm(q["eye_inner_L"] - q["eye_inner_R"])) if "eye_inner_L" in q else 0.0
        src_span = float(np.ptp([q[n][0] for n in mouth])) / src_es if src_es > 0 else 0.0
        if proportions and src_span > 0 and span < MOUTH_SPAN * src_span:
            out.append({"points": mouth, "why": f"the mouth's points are crowded into {span:.2f} inner-eye distances "
                                                f"across (the source's {src_span:.2f}): the mouth is drawn very small "
                                                "or the points missed it; the cloned mouth can only be as good as "
                                                "they are"})
        ys = np.array([p[n][1] for n in mouth])
        src = np.array([q[n] for n in mouth])
        src_ratio = float(np.ptp(src[:, 1]) / max(np.ptp(src[:, 0]), 1e-12))
        ratio = float(np.ptp(ys) / max(np.ptp(xs), 1e-12))
        if proportions and ratio < FLAT_MOUTH * src_ratio:
            out.append({"points": mouth, "why": f"the mouth's points lie on a line: their height is {ratio:.2f} of "
                                                f"their width (the source's {src_ratio:.2f}); the lips cannot be told "
                                                "apart"})
    for up_name, low_name in (("lip_upper", "lip_lower"), ("lip_upper_L", "lip_lower_L"),
                              ("lip_upper_R", "lip_lower_R")):
        if up_name in p and low_name in p and p[low_name][1] > p[up_name][1] - tie:
            out.append({"points": [up_name, low_name], "why": "the upper lip is not above the lower one"})
    return out


def decal_doubts(target: np.ndarray, names: Sequence[str], eyes: dict, mouth: tuple | None) -> list[dict]:
    """Doubts for points of a decal face off what is drawn: an eye's corners and lids outside its box (``eyes``:
    :attr:`~.pieces.Pieces.eyes`, boxes in the face frame) grown by ``DECAL_MARGIN`` of its size, the mouth's
    points beyond its ends (``mouth``: :attr:`~.pieces.Pieces.mouth`) or further from its line than
    ``DECAL_MARGIN`` of its width (``target``: front view (n, 2) in ``names``' order)."""
    p = {n: np.asarray(target[i], np.float64) for i, n in enumerate(names)}
    out = []
    for side, (_, (x0, x1, y0, y1)) in eyes.items():
        mx, my = DECAL_MARGIN * (x1 - x0), DECAL_MARGIN * (y1 - y0)
        own = [n for n in p if n.endswith("_" + side) and n.startswith(("eye_inner", "eye_outer", "lid_"))]
        off = [n for n in own if not (x0 - mx <= p[n][0] <= x1 + mx and y0 - my <= p[n][1] <= y1 + my)]
        if off:
            out.append({"points": off, "why": f"off the drawn {'left' if side == 'L' else 'right'} eye: outside its "
                                              f"outline's box (grown by {DECAL_MARGIN:.0%}); the lids must lie on "
                                              "the eye's opening"})
    if mouth is not None:
        _, (xr, xl), line = mouth
        m = DECAL_MARGIN * (xl - xr)
        own = [n for n in p if feature_of(n) == "mouth"]
        off = [n for n in own if not (xr - m <= p[n][0] <= xl + m and abs(p[n][1] - np.polyval(line, p[n][0])) <= m)]
        if off:
            out.append({"points": off, "why": f"off the drawn mouth: beyond its ends or its line (by more than "
                                              f"{DECAL_MARGIN:.0%} of its width)"})
    return out


def by_feature(doubts: list[dict], names: Sequence[str]) -> list[dict]:
    """``doubts`` with the poor local fits (those with a "residual") of one feature merged into one, naming its
    points worst first, and all of its points (of ``names``) when half of them fit poorly (the feature as a
    whole is laid out otherwise than the source's); the others as they are."""
    merged: dict = {}
    out = []
    for d in doubts:
        if "residual" not in d:
            out.append(d)
            continue
        f = feature_of(d["points"][0])
        if f not in merged:
            merged[f] = {"points": [], "residual": d["residual"], "why": d["why"]}
            out.append(merged[f])
        merged[f]["points"] += [n for n in d["points"] if n not in merged[f]["points"]]
    for f, d in merged.items():
        members = [n for n in names if feature_of(n) == f]
        if f != "other" and 2 * len(d["points"]) >= len(members):
            d["points"] += [n for n in members if n not in d["points"]]
            d["why"] = (f"poor local fit of the {f} as a whole: its points are up to {d['residual']:.2f} of their "
                        "neighbours' spacing from where the source's layout puts them: the feature is laid out "
                        "otherwise than the source's, so its cloned motion is the source's at the wrong proportions")
        elif len(d["points"]) > 1:
            d["why"] = (f"poor local fit of the {f}: these points are up to {d['residual']:.2f} of their neighbours' "
                        "spacing from where the source's layout puts them: another place or proportions than the "
                        "source's")
    return out
