"""A blink's lids meet along the whole lid, measured on the character itself (:mod:`.lid_seal`).

On a made-up face (a flat skin with two eye holes) a blink that leaves the middle of the lid open is closed
column by column, the lower lid and the skin away from the eye untouched. On a head of real other proportions
held out from the design (ICT warped 1.5 times towards the MediaPipe face), the cloned blink used to leave
0.156 cm of a 0.615 cm gap at the middle of the left lid while its lid points met (the points sit elsewhere
along the lid than the true ones); with the seal it closes.
"""

import json

import numpy as np
import pytest

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ControlPoints, ict_control_points
from facepuppet.offline.elastic.params import fit_character
from facepuppet.offline.io.obj import read_vertices_only
from facepuppet.offline.perfect_sync import evaluate
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.lid_seal import FADE, lid_margins, seal_blink
from facepuppet.offline.perfect_sync.real_variants import real_variants
from tests.conftest import need_shared

CLOSED = 0.05


def _eyed_sheet():
    """A flat skin (face frame = world) with two lens-shaped holes 1 unit wide, 0.3 tall, centred at x = ±0.8;
    their six eye points each, the lid points a third and two thirds of the way along the lids."""
    xs, ys = np.linspace(-2, 2, 161), np.linspace(-1, 1, 81)
    gx, gy = np.meshgrid(xs, ys)
    v = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    nx = len(xs)
    q = [(r * nx + c, r * nx + c + 1, (r + 1) * nx + c + 1, (r + 1) * nx + c) for r in range(len(ys) - 1)
         for c in range(nx - 1)]
    q = np.asarray(q)

    def half_height(x, cx):
        u = (x - cx) / 0.5
        return np.where(np.abs(u) < 1, 0.15 * (1 - u**2), -1.0)

    centre = v[q].mean(1)
    hole = np.zeros(len(q), bool)
    for cx in (-0.8, 0.8):
        hole |= np.abs(centre[:, 1]) < half_height(centre[:, 0], cx)
    q = q[~hole]
    tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    names, idx = [], []
    for side, cx in (("L", 0.8), ("R", -0.8)):
        sgn = 1 if side == "L" else -1
        at = {"eye_inner": (cx - sgn * 0.5, 0.0), "eye_outer": (cx + sgn * 0.5, 0.0)}
        for part, u in (("inner", -1 / 3), ("outer", 1 / 3)):
            x = cx + sgn * u * 0.5
            h = 0.15 * (1 - (u) ** 2)
            at[f"lid_upper_{part}"], at[f"lid_lower_{part}"] = (x, h), (x, -h)
        for n, p in at.items():
            names.append(f"{n}_{side}")
            idx.append(int(np.argmin(np.hypot(v[:, 0] - p[0], v[:, 1] - p[1]))))
    return v, tri, ControlPoints(tuple(names), np.asarray(idx))


def _gap(v, tri, d, x):
    """The vertical gap between the lids' margin vertices in column ``x`` of the left eye, rest and shaped."""
    used = np.zeros(len(v), bool)
    used[tri] = True
    col = (np.abs(v[:, 0] - x) < 1e-6) & used
    above = col & (v[:, 1] > 0)
    below = col & (v[:, 1] < 0)
    up = np.flatnonzero(above)[np.argmin(v[above, 1])]
    low = np.flatnonzero(below)[np.argmax(v[below, 1])]
    return v[up, 1] - v[low, 1], v[up, 1] + d[up, 1] - v[low, 1] - d[low, 1]


def test_a_blink_left_open_in_the_middle_is_closed_column_by_column():
    v, tri, points = _eyed_sheet()
    skin = np.arange(len(v))
    margins = lid_margins(v, tri, skin, points)
    assert set(margins) == {"L", "R"}
    # a blink that brings the upper lid only half way down, less and less above the margin
    d = np.zeros_like(v)
    u = (v[:, 0] - 0.8) / 0.5
    upper = (v[:, 1] > 0) & (np.abs(u) < 1)
    margin = 0.15 * np.clip(1 - u**2, 0, None)
    d[upper, 1] = -margin[upper] * np.exp(-np.clip(v[upper, 1] - margin[upper], 0, None) / 0.3)
    rest, before = _gap(v, tri, d, 0.8)
    assert before > 0.3 * rest  # the middle stays open
    out = d.copy()
    largest = seal_blink(out, "eyeBlinkLeft", v, skin, margins, np.eye(3), CLOSED)
    assert largest > 0.1
    for x in np.linspace(0.65, 0.95, 7):  # the middle of the lid, where the columns are plain
        rest, after = _gap(v, tri, out, round(x / 0.025) * 0.025)
        assert abs(after - CLOSED * rest) < 0.02 * rest, (x, rest, after)
    m = margins["L"]  # and at every pair of margin vertices the seal found, out to the corners
    rest = v[m["upper"], 1] - v[m["lower"], 1]
    after = rest + out[m["upper"], 1] - out[m["lower"], 1]
    assert np.all(np.abs(after - CLOSED * rest) < 0.1 * rest + 0.01), np.c_[rest, after]
    moved = np.linalg.norm(out - d, axis=1) > 1e-9
    assert not (moved & (v[:, 1] < 0)).any()  # the lower lid keeps the clone's motion
    assert not (moved & (v[:, 0] < 0)).any()  # the other eye too
    es = 1.6
    assert not (moved & (v[:, 1] > 0.15 + FADE * es + 1e-9)).any()  # faded to nothing above the lid
    # a blink whose lids already meet (between 0 and CLOSED of the gap: the sealed one) is left as it is
    kept = out.copy()
    assert seal_blink(kept, "eyeBlinkLeft", v, skin, margins, np.eye(3), CLOSED) < 1e-9
    np.testing.assert_allclose(kept, out, atol=1e-9)
    # a shape that is no blink, and a face with no opening, are left alone
    assert seal_blink(d.copy(), "eyeSquintLeft", v, skin, margins, np.eye(3), CLOSED) is None
    closed_tri = np.concatenate([tri, [[0, 1, 2]]])[:0]
    assert lid_margins(v, closed_tri, skin, points) == {}


@pytest.mark.slow  # the ICT fit, a warp of its 53 shapes and a clone of 26k vertices
def test_the_cloned_blinks_close_the_lids_on_a_held_out_head(ict_character):
    data = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    marks = np.asarray(data["idx_to_landmark_verts"], np.int64)
    c = ict_character
    source = fit_character(c, ict_control_points(marks, c.vertices, c.triangles, main_front(c)),
                           with_muscles=False)[0]
    mediapipe = read_vertices_only(need_shared("mediapipe", "canonical_face_model.obj"), 468)
    [(_, variant, _)] = real_variants(c, marks, mediapipe, ["mediapipe_strong"])
    target = variant.with_parts(shape_names=tuple(f"truth{i}" for i in range(variant.n_shapes)), expressions=None)
    out, report, _ = perfect_sync(target, source)
    face = find_face(variant)
    points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    lids = evaluate.lid_closure(variant, out, face, points)
    assert set(lids) == {"eyeBlinkLeft", "eyeBlinkRight"}
    for key, gap in lids.items():
        # measured 0.092 / 0.025 cm of a 0.615 cm rest gap (true 0.092); before the seal 0.156 on the left
        assert abs(gap["cloned"]) < 0.25 * gap["rest"], (key, gap)
    errs = evaluate.truth_errors(variant, out, face)
    assert np.median(list(errs.values())) < 0.15 and max(errs.values()) < 0.40
