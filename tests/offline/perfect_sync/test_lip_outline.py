"""The outer lip points checked against the lips' outline in the skin (lip_outline.py): a lip point moved up is
named, with its reason, and marked in the landmarks picture; lips thinner than the source's in its layout are
named; the true points are not.

Designed on the ICT head (its kit landmarks) and the MediaPipe canonical face (its lip vertices of known meaning);
measured afterwards on the actor-face head (``animface``), whose proposed outer lips were 0.73-1.09 cm off in
height and "0 doubtful"."""

import json

import numpy as np
import pytest
from PIL import Image

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ControlPoints, ict_control_points
from facepuppet.offline.io.capture import read_trc
from facepuppet.offline.io.rig_import import import_rig
from facepuppet.offline.perfect_sync.doubt_measure import moved, named_far
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import doubts, picture, propose, skin_triangles
from facepuppet.offline.perfect_sync.real_variants import MULTIPIE_TO_MARKERS, marker_variants
from tests.conftest import need_shared

pytestmark = pytest.mark.data

LIPS = ("lip_upper", "lip_upper_L", "lip_upper_R", "lip_lower", "lip_lower_L", "lip_lower_R")
#: MediaPipe face-mesh vertices of the mouth's points (the subject's right is R)
MEDIAPIPE_MOUTH = {"mouth_corner_R": 61, "mouth_corner_L": 291, "lip_upper_inner": 13, "lip_lower_inner": 14,
                   "lip_upper": 0, "lip_upper_L": 267, "lip_upper_R": 37, "lip_lower": 17, "lip_lower_L": 314,
                   "lip_lower_R": 84}


@pytest.fixture(scope="module")
def marks():
    data = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    return np.asarray(data["idx_to_landmark_verts"], np.int64)


@pytest.fixture(scope="module")
def ict(ict_character, marks):
    c = ict_character
    points = ict_control_points(marks, c.vertices, c.triangles, main_front(c))
    return c, find_face(c), points


def _lip_doubts(found: list[dict]) -> dict:
    return {d["points"][0]: d["why"] for d in found if d["why"].startswith("off the lip's outline")}


def test_icts_true_lip_points_are_on_the_outline(ict):
    c, face, points = ict
    found = doubts(points, c.vertices, face, source_positions=c.vertices[points.vertices])
    assert _lip_doubts(found) == {}, found


@pytest.mark.parametrize("name", LIPS)
def test_a_lip_point_moved_up_on_ict_is_named_off_the_outline_and_marked(ict, name, tmp_path):
    """1 cm up, the local fit named it before too (0.75-0.92 of its neighbours' spacing); 0.6 cm up nothing did.
    Both are named now, as off the lip's outline, and only that point is."""
    c, face, points = ict
    v = c.vertices.astype(np.float64)
    for cm in (1.0, 0.6):  # ICT is in cm
        wrong = moved(points, v, face.skin, name, v[points.vertex(name)] + cm * face.frame[1])
        found = doubts(wrong, v, face, source_positions=v[points.vertices])
        lips = _lip_doubts(found)
        assert name in lips, (cm, found)
        assert "of the mouth's width" in lips[name]
        assert set(lips) == {name}, (cm, lips)  # the point moved, not its neighbours
    if name == "lip_upper":  # the picture marks it: a red ring where the point is drawn
        path = picture(tmp_path / "landmarks.png", v, face, wrong, [n for d in found for n in d["points"]], found)
        img = np.asarray(Image.open(path).convert("RGB")).astype(int)
        red = (img[..., 0] > 200) & (img[..., 1] < 80) & (img[..., 2] < 80)
        assert red[:720].sum() > 50


def test_thinner_lips_laid_out_as_the_sources_are_named_on_ict(ict):
    """The actor head's case: every outer lip point at 60 % of its height over the mouth's line, the layout's
    shape kept (so no local fit sees it): all six named (before: none)."""
    c, face, points = ict
    v = c.vertices.astype(np.float64)
    line = 0.5 * (v[points.vertex("lip_upper_inner")] + v[points.vertex("lip_lower_inner")]) @ face.frame[1]
    wrong = points
    for name in LIPS:
        p = v[points.vertex(name)]
        wrong = moved(wrong, v, face.skin, name, p - 0.4 * (p @ face.frame[1] - line) * face.frame[1])
    found = doubts(wrong, v, face, source_positions=v[points.vertices])
    assert set(LIPS) <= {n for d in found for n in d["points"]}, found


@pytest.fixture(scope="module")
def mediapipe(ict):
    """(face mesh, face, points): the proposal with the mouth's points on MediaPipe's vertices of that meaning."""
    c, _, truth = ict
    mp = import_rig(need_shared("mediapipe", "canonical_face_model.obj"), None)
    face = find_face(mp)
    layout = c.vertices[truth.vertices].astype(np.float64)
    points, _ = propose(layout, truth.names, mp.vertices, face, find_pieces(mp.vertices, face, skin_triangles(face)))
    known = points.vertices.copy()
    for n, i in MEDIAPIPE_MOUTH.items():
        known[points.index(n)] = i
    return mp, face, ControlPoints(points.names, known), layout


def test_mediapipes_known_lip_points_are_on_the_outline_and_one_moved_1_cm_up_is_named(mediapipe):
    mp, face, points, layout = mediapipe
    v = mp.vertices.astype(np.float64)
    assert _lip_doubts(doubts(points, v, face, source_positions=layout)) == {}
    for name in ("lip_upper", "lip_lower_L"):
        wrong = moved(points, v, face.skin, name, v[points.vertex(name)] + 1.0 * face.frame[1])  # in cm
        found = doubts(wrong, v, face, source_positions=layout)
        assert name in _lip_doubts(found), (name, found)


def test_the_actor_heads_misplaced_outer_lips_are_named_and_its_true_points_are_not(ict_character, marks, ict):
    """Measured on the held-out actor head after the check was set on ICT and MediaPipe: its proposed outer lips
    are 0.73-1.09 cm off (before: none named, "0 doubtful"); named now: the lower three and the upper middle
    (the upper sides, 1.08 cm off mostly across, sit on the outline of the column they are in: missed)."""
    take = read_trc(need_shared("markers", "animface_jaw.trc"))
    markers = {n: take.markers[0, take.names.index(n)].astype(np.float64) for _, n in MULTIPIE_TO_MARKERS}
    [(_, variant, _)] = marker_variants(ict_character, marks, markers, ["animface"])
    _, _, truth = ict
    layout = ict_character.vertices[truth.vertices].astype(np.float64)
    face = find_face(variant)
    v = variant.vertices.astype(np.float64)
    proposed, fitted = propose(layout, truth.names, v, face, find_pieces(v, face, skin_triangles(face)))
    true = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant)).reorder(truth.names)
    r = named_far(proposed, true, v, doubts(proposed, v, face, fitted, source_positions=layout),
                  doubts(true, v, face, source_positions=layout))
    assert r["true_points_doubted"] == [], r
    assert {"lip_upper", "lip_lower", "lip_lower_L", "lip_lower_R"} <= set(r["far_named"]), r
