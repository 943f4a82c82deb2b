"""A second face for the real-proportion variants, independent of MediaPipe's: the actor of the kit's AnimFace
marker take (its neutral first frame), whose markers near 23 of the Multi-PIE landmarks move ICT's."""

import json

import numpy as np
import pytest

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.io.capture import read_trc
from facepuppet.offline.perfect_sync import evaluate
from facepuppet.offline.perfect_sync.bench import _marker_heads, _with_true_points
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.proposal import propose
from facepuppet.offline.perfect_sync.real_variants import MULTIPIE_TO_MARKERS, marker_variants, similarity
from facepuppet.offline.perfect_sync.source import fit_kit_source
from tests.conftest import need_shared


@pytest.fixture(scope="module")
def marks():
    data = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    return np.asarray(data["idx_to_landmark_verts"], np.int64)


@pytest.fixture(scope="module")
def markers():
    take = read_trc(need_shared("markers", "animface_jaw.trc"))
    return {n: take.markers[0, take.names.index(n)].astype(np.float64) for _, n in MULTIPIE_TO_MARKERS}


def test_the_markers_sit_near_their_landmarks_on_the_right_side(ict_character, marks, markers):
    """After a similarity each marker lies within 2 cm of its ICT landmark (measured 0.31-1.73; the eye corners'
    markers 1.4 cm in front: on the skin, not in the corner), every left marker on the character's left (+x)."""
    idx = [i for i, _ in MULTIPIE_TO_MARKERS]
    a = ict_character.vertices[marks[idx]].astype(np.float64)
    b = similarity(np.asarray([markers[n] for _, n in MULTIPIE_TO_MARKERS]), a)
    assert np.linalg.norm(b - a, axis=1).max() < 2.0
    for (_, name), p in zip(MULTIPIE_TO_MARKERS, b):
        if name.startswith("L") or name.endswith(("_L", "Lend", "L1", "DownL")):
            assert p[0] > 0, name
        if name.startswith("R") or name.endswith(("_R", "Rend", "R1", "DownR")):
            assert p[0] < 0, name


def test_the_variants_change_proportions_without_folding_and_keep_icts_depth_at_the_landmarks(ict_character, marks,
                                                                                                markers):
    heads = marker_variants(ict_character, marks, markers)
    assert [h[0] for h in heads] == ["animface", "animface_half"]
    moved = {}
    for label, variant, folded in heads:
        assert folded == 0.0, label
        d = variant.vertices.astype(np.float64) - ict_character.vertices
        moved[label] = np.linalg.norm(d, axis=1)
        # only the front-view places move the landmarks: their depth change is the spline's smoothing, small
        idx = [i for i, _ in MULTIPIE_TO_MARKERS]
        assert np.abs(d[marks[idx], 2]).max() < 0.2, label
        assert variant.n_shapes == ict_character.n_shapes
    assert moved["animface"].max() > 1.0  # cm: a real change (measured 3.0 at most, 0.76 median)
    np.testing.assert_allclose(moved["animface_half"], 0.5 * moved["animface"], rtol=0.02, atol=1e-3)


@pytest.mark.slow  # the kit source's fit (cached) and a clone of 26k vertices
def test_the_held_out_actor_head_blinks_close_and_no_shape_is_over_40(ict_character, marks, markers):
    """Measured: median 13.1 %, worst eyeBlinkLeft 29.0 %; blink mid-lid gaps 0.14 / 0.05 cm of 1.03 / 1.01
    (true 0.15 / 0.13). Before the eyes were moved by their markers' centre and the proposal took the eye's outer
    corner and the mouth's corners at their openings' ends: median 19.8 %, worst 33.1 %, gaps 0.09 / 0.17 cm of
    1.08 / 1.06 (without the lid seal 0.00 / 0.31).
    While the seal took its margins anywhere seen from the front, the socket behind the eyeball seen at the
    opening's edge was taken for one and the left blink was torn open to 0.29."""
    [(_, variant, _)] = marker_variants(ict_character, marks, markers, ["animface"])
    target = variant.with_parts(shape_names=tuple(f"truth{i}" for i in range(variant.n_shapes)), expressions=None)
    out, _, _ = perfect_sync(target, fit_kit_source(need_shared("ict-facekit")))
    face = find_face(variant)
    points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    for key, gap in evaluate.lid_closure(variant, out, face, points).items():
        assert abs(gap["cloned"]) < 0.25 * gap["rest"], (key, gap)
    # and along the whole lid, from the true inner to the true outer lid points (measured at most 0.17 of the
    # rest gap; before the seal took the outer corner from the opening, the right outer lid stayed 1.14 open)
    v, up, skin = variant.vertices.astype(np.float64), face.frame[1], face.skin
    dense = out.dense_deltas()
    names = list(out.shape_names)

    def near(p):
        return int(skin[np.argmin(np.linalg.norm(v[skin] - p, axis=1))])

    for key, side in (("eyeBlinkLeft", "L"), ("eyeBlinkRight", "R")):
        d = dense[names.index(key, variant.n_shapes)]
        for f in (0.0, 0.25, 0.5, 0.75, 1.0):
            a, b = (near((1 - f) * v[points.vertex(f"lid_{lid}_inner_{side}")] + f * v[points.vertex(
                f"lid_{lid}_outer_{side}")]) for lid in ("upper", "lower"))
            rest = (v[a] - v[b]) @ up
            assert abs((v[a] + d[a] - v[b] - d[b]) @ up) < 0.25 * rest, (key, f, rest)
    errs = evaluate.truth_errors(variant, out, face)
    assert max(errs.values()) < 0.40, max(errs.items(), key=lambda kv: kv[1])


def test_the_bench_says_when_the_take_is_missing_or_not_asked_for(ict_character, marks, tmp_path):
    out: dict = {}
    assert _marker_heads(tmp_path / "none.trc", ict_character, marks, ["animface"], out) == []
    assert "none.trc not in the data kit" in out["note_markers"]
    out = {}
    assert _marker_heads(tmp_path / "none.trc", ict_character, marks, ["mediapipe"], out) == [] and out == {}
    take = need_shared("markers", "animface_jaw.trc")
    [(label, _, folded)] = _marker_heads(take, ict_character, marks, ["animface_half"], out)
    assert label == "animface_half" and folded == 0.0 and out == {}


def test_the_actor_variant_keeps_a_human_eye_and_nose(ict_character, marks, markers):
    """The eye-corner markers sit on the skin outside the corners (4.5-5.0 cm apart after the alignment, where an
    eye opening is about 3) and the nose-wing markers on the alae: taken as the corners they made 5 cm eyes
    whose inner corners lay on the nose bridge. Each pair moves its feature by its centre, so the variant's eye
    opening (corner to corner) stays within a human share of the inner-eye distance (ICT 0.73; measured 0.67
    and 0.70 after; 1.9 before) and its nose as wide as ICT's within 10 %."""
    for _, variant, _ in marker_variants(ict_character, marks, markers):
        points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
        v = variant.vertices.astype(np.float64)

        def gap(a, b, v=v, points=points):
            return float(np.linalg.norm(v[points.vertex(a)] - v[points.vertex(b)]))

        es = gap("eye_inner_L", "eye_inner_R")
        for side in ("L", "R"):
            assert 0.5 <= gap(f"eye_inner_{side}", f"eye_outer_{side}") / es <= 1.0, side
        ict_nose = float(np.linalg.norm(np.subtract(*ict_character.vertices[marks[[31, 35]]].astype(np.float64))))
        assert abs(float(np.linalg.norm(v[marks[31]] - v[marks[35]])) / ict_nose - 1.0) < 0.1


def test_the_proposed_eye_points_sit_on_the_actor_heads_eyes(ict_character, marks, markers):
    """The coarse fit lands the actor head's eyes 1 cm high and narrower than they are; snapped to the opening's
    pixel nearest the fit's corner, the corners stayed inside the opening, up to 1.06 cm from the true ones
    (the right outer corner). The outer corner is the opening's end and the inner one is sought from the fit
    moved as the outer corner moved: measured at most 0.21 cm (animface) and 0.19 (animface_half). The mouth's
    corners likewise stayed inside its slit, 0.79 cm off; taken at the slit's ends, at most 0.16. The cheeks'
    proposed places (before each takes a skin vertex), left where the fit put the eyes, lay a mean 1.07 cm off;
    moved between the found eyes and mouth, 0.81."""
    source = fit_kit_source(need_shared("ict-facekit"))
    names = tuple(source.control_names)
    for label, variant, _ in marker_variants(ict_character, marks, markers):
        face = find_face(variant)
        proposed, fitted = propose(source.arrays["control_positions"], names, variant.vertices, face)
        true = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant)).reorder(names)
        v = variant.vertices.astype(np.float64)
        for name in names:
            if name.startswith(("eye_", "lid_", "mouth_corner")):
                assert np.linalg.norm(v[proposed.vertex(name)] - v[true.vertex(name)]) < 0.3, (label, name)
        if label == "animface":
            cheeks = [names.index(n) for n in names if n.startswith("cheek")]
            assert np.linalg.norm(fitted[cheeks] - v[true.vertices[cheeks]], axis=1).mean() < 0.95


@pytest.mark.slow  # a clone of 26k vertices
def test_given_its_true_points_the_actor_head_clones_within_the_goal(ict_character, marks, markers):
    """The bench's split of a set's error (``true_points``): with the true control points the actor head's clone
    meets the goal (measured median 13.7 %, worst eyeBlinkRight 24.4 %), so what it misses beyond is the
    proposal's."""
    [(_, variant, _)] = marker_variants(ict_character, marks, markers, ["animface"])
    points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    got = _with_true_points(variant, fit_kit_source(need_shared("ict-facekit")), points, find_face(variant))
    assert got["median"] < 0.15 and got["worst"][1] < 0.40, got
