"""A decal face's features moved by a landmark field of the source's control points.

Decal features move by a **landmark field** (:func:`feature_field`): the
source's control points are placed on the target relative to the features
(eye points by their place in the source eye's box of corners and lids,
mouth points relative to the mouth corners and lip line, the others by
the affine map these define), each control point's cloned displacement is
scaled by its feature's size against the source's (an anime eye three
times as tall as ICT's closes three times as far), and a thin-plate
spline over the face's front plane interpolates them. The blinks' upper
lid points are put onto the lower ones (the lids meet), and the field is
**cut along the lip line**: a vertex above the mouth's line (a quadratic
through the mouth pieces' vertices, with half of them above it) takes the
field of the upper lip, one below it that of the lower lip and jaw (or the
side :func:`~.pieces.mouth_sides` gave it), so the mouth opens between its
lips even where they lie on one line at rest; likewise only the eye's own
pieces follow the lid points (a brow piece just above the lashes does not),
and an eye piece beyond the eye's box (the lashes above the upper lid)
moves as the box's edge does.

A decal mouth opens in the jaw's shapes (``JAW_OPENINGS`` of
:mod:`.transfer`) by the lips' motion relative to each other: the skin
around it does not move (no mouth hole, no lips), so the jaw's drop, the
lip line's own motion (:func:`lip_line_motion`), is taken out and the
mouth opens about its line. (Measured on Godette, mouth pieces only:
cosine to her "ah" 0.24 with the jaw's drop, 0.48 without; projecting the
motion onto the skin's tangent plane as well gave 0.47, so it is not done.
Her artist also widens the mouth by half, which no source shape says.)
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RBFInterpolator

from facepuppet.offline.perfect_sync.drawn_eyes import CLOSED
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.pieces import Pieces

EYE_NAMES = ("eye_inner", "eye_outer", "lid_upper_inner", "lid_upper_outer", "lid_lower_inner", "lid_lower_outer")
MOUTH_NAMES = ("mouth_corner", "lip_upper", "lip_lower", "mouth_inner")  # prefixes
LOWER_JAW = ("lip_lower", "chin", "jaw_chin")  # prefixes of the points below the lip line


def _prefixed(name: str, prefixes: tuple) -> bool:
    return any(name == p or name.startswith(p + "_") for p in prefixes)


def feature_places(pieces: Pieces, source_positions: np.ndarray, names: tuple) -> tuple[np.ndarray, np.ndarray,
                                                                                           np.ndarray]:
    """Where the source's control points lie on a decal face, relative to its features (see the module doc):
    (places (n_c, 2) x, y in the face frame; scales (n_c, 3) of their displacements; placed by a feature (n_c,)
    bool, the others by the affine map these define). Places are NaN when fewer than 3 are placed."""
    src = np.asarray(source_positions, np.float64)
    idx = {n: i for i, n in enumerate(names)}
    n_c = len(names)
    pos = np.full((n_c, 2), np.nan)  # target places in the face frame (x, y)
    scale = np.full((n_c, 3), np.nan)
    for side, (_, (x0, x1, y0, y1)) in pieces.eyes.items():
        sign = 1.0 if side == "L" else -1.0
        need = [f"{n}_{side}" for n in EYE_NAMES]
        if not all(n in idx for n in need):
            continue
        s_in, s_out = src[idx[f"eye_inner_{side}"]], src[idx[f"eye_outer_{side}"]]
        s_low = np.mean([src[idx[f"lid_lower_{p}_{side}"]][1] for p in ("inner", "outer")])
        s_up = np.mean([src[idx[f"lid_upper_{p}_{side}"]][1] for p in ("inner", "outer")])
        t_in, t_out = (x0, x1) if sign > 0 else (x1, x0)
        sx = abs(t_out - t_in) / max(abs(s_out[0] - s_in[0]), 1e-12)
        sy = (y1 - y0) / max(s_up - s_low, 1e-12)
        for name in names:
            if not name.endswith("_" + side) or not (_prefixed(name[:-2], EYE_NAMES) or name.startswith("brow")):
                continue
            p = src[idx[name]]
            u = (p[0] - s_in[0]) / (s_out[0] - s_in[0])
            if name.startswith("brow"):  # above the upper lid by the source's gap, in the eye's width scale
                y = y1 + (p[1] - s_up) * sx
            else:
                y = y0 + (p[1] - s_low) / (s_up - s_low) * (y1 - y0)
            pos[idx[name]] = (t_in + u * (t_out - t_in), y)
            scale[idx[name]] = (sx, sy if not name.startswith("brow") else sx, sx)
    if pieces.mouth is not None and all(n in idx for n in ("mouth_corner_L", "mouth_corner_R",
                                                          "lip_upper_inner", "lip_lower_inner")):
        _, (xr, xl), line = pieces.mouth
        s_r, s_l = src[idx["mouth_corner_R"]], src[idx["mouth_corner_L"]]
        s_line = 0.5 * (src[idx["lip_upper_inner"]][1] + src[idx["lip_lower_inner"]][1])
        sm = (xl - xr) / max(s_l[0] - s_r[0], 1e-12)
        for name in names:
            if not (_prefixed(name, MOUTH_NAMES) or _prefixed(name, LOWER_JAW)):
                continue
            p = src[idx[name]]
            x = xr + (p[0] - s_r[0]) / (s_l[0] - s_r[0]) * (xl - xr)
            pos[idx[name]] = (x, np.polyval(line, x) + (p[1] - s_line) * sm)
            scale[idx[name]] = sm
    placed = ~np.isnan(pos[:, 0])
    if placed.sum() < 3:
        return pos, scale, placed
    # the others by the affine map the placed ones define, at their mean scale
    a = np.column_stack([src[placed, :2], np.ones(placed.sum())])
    affine = np.linalg.lstsq(a, pos[placed], rcond=None)[0]
    rest = ~placed
    pos[rest] = np.column_stack([src[rest, :2], np.ones(rest.sum())]) @ affine
    scale[rest] = float(np.sqrt(abs(np.linalg.det(affine[:2]))))
    return pos, scale, placed


def feature_field(pieces: Pieces, face: Face, vertices: np.ndarray, source_positions: np.ndarray,
                  names: tuple, params: np.ndarray, shape_names: tuple, targets: np.ndarray,
                  places: np.ndarray | None = None, below: np.ndarray | None = None) -> np.ndarray:
    """Displacements (n_shapes, len(targets), 3) in world axes of the ``targets`` vertices by the landmark field
    (see the module doc). ``params``: the source's (n_shapes, n_c, 3), source units and axes (+Y up, +Z
    forward); ``source_positions`` (n_c, 3). ``places`` (len(targets), 2), when given, are where (x, y in the
    face frame) the field is evaluated instead of at the targets, and ``below`` (bool) which side of the lip
    line's cut each takes instead of the side it lies on."""
    prm = np.asarray(params, np.float64)
    idx = {n: i for i, n in enumerate(names)}
    v = np.asarray(vertices, np.float64)
    local = face.to_frame(v)
    n_c = len(names)
    lower = np.array([_prefixed(n, LOWER_JAW) for n in names])
    upper_lip = np.array([_prefixed(n, ("lip_upper",)) for n in names])
    line = pieces.mouth[2] if pieces.mouth is not None and all(n in idx for n in (
        "mouth_corner_L", "mouth_corner_R", "lip_upper_inner", "lip_lower_inner")) else None
    pos, scale, placed = feature_places(pieces, source_positions, names)
    if placed.sum() < 3:
        return np.zeros((len(prm), len(targets), 3))
    disp = prm * scale[None]  # (s, n_c, 3) in the source's axes = the face frame's
    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        if key not in shape_names or side not in pieces.eyes:
            continue
        s = shape_names.index(key)
        for part in ("inner", "outer"):
            i, j = idx[f"lid_upper_{part}_{side}"], idx[f"lid_lower_{part}_{side}"]
            gap = pos[i, 1] - pos[j, 1]
            disp[s, i, 1] = pos[j, 1] + disp[s, j, 1] + CLOSED * gap - pos[i, 1]
    tgt = local[np.asarray(targets, np.int64)]
    if places is not None:
        tgt = np.column_stack([np.asarray(places, np.float64)[:, :2], tgt[:, 2]])
    out = np.zeros((len(prm), len(tgt), 3))
    flat = disp.transpose(1, 0, 2).reshape(n_c, -1)
    if below is None:
        below = np.zeros(len(tgt), bool) if line is None else tgt[:, 1] < np.polyval(line, tgt[:, 0])
        if line is not None and len(pieces.mouth_below):  # the mouth's vertices: the side mouth_sides gave them
            side = dict(zip(pieces.mouth[0].tolist(), pieces.mouth_below.tolist()))
            below = np.array([side.get(int(t), b) for t, b in zip(np.asarray(targets).tolist(), below)], bool)
    eye_members = [m for m, _ in pieces.eyes.values()]
    in_eye = np.isin(targets, np.concatenate(eye_members)) if eye_members else np.zeros(len(tgt), bool)
    lids = np.array([n.startswith("lid_") for n in names])
    for is_below in (False, True):
        for inside in (False, True):
            where = (below == is_below) & (in_eye == inside)
            if not where.any():
                continue
            keep = ~(upper_lip if is_below else lower) if line is not None else np.ones(n_c, bool)
            if not inside:
                keep &= ~lids  # the lids are the eye's moving edge: what is not the eye (a brow) does not follow them
            at = tgt[where, :2].copy()
            if inside:  # an eye piece beyond the lid points (the lashes above the upper lid) moves as the lid
                for m, (x0, x1, y0, y1) in pieces.eyes.values():
                    mine = np.isin(np.asarray(targets)[where], m)
                    at[mine] = np.clip(at[mine], [x0, y0], [x1, y1])
            rbf = RBFInterpolator(pos[keep], flat[keep], kernel="thin_plate_spline", smoothing=0.0, degree=1)
            out[:, where] = rbf(at).reshape(where.sum(), len(prm), 3).transpose(1, 0, 2)
    return out @ face.frame  # face-frame axes back to world


def lip_line_motion(pieces: Pieces, face: Face, vertices: np.ndarray, source_positions: np.ndarray,
                    names: tuple, params: np.ndarray, shape_names: tuple) -> np.ndarray:
    """The decal mouth's line's own motion under each vertex of the mouth: (n_shapes, m, 3) in world axes, the
    mean of the upper lip's field and the lower lip's (:func:`feature_field`) on the lip line at the vertex's
    place across the face. What a vertex's field adds to it is the lips' motion relative to each other."""
    m = pieces.mouth[0]
    x = face.to_frame(np.asarray(vertices, np.float64)[m])[:, 0]
    on = np.column_stack([x, np.polyval(pieces.mouth[2], x)])
    args = (pieces, face, vertices, source_positions, names, params, shape_names, m, on)
    return 0.5 * (feature_field(*args, below=np.zeros(len(m), bool)) + feature_field(*args, below=np.ones(len(m),
                                                                                                           bool)))
