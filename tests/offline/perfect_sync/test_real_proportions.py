"""perfect-sync on a head of real other proportions whose true shapes are known: the ICT head warped towards the
MediaPipe face's eyes and lip line (1.5 times the way), its shapes carried by the same warp.

The cloning was designed on another variant (the whole face, once the way: ``bench perfect-sync``'s
"mediapipe"); this one is held out. Before the eye and mouth points were put on the lid margins and the lips'
crease, this head cloned at a median 18 % with 6 shapes over 40 % (eye looks 62 %, blinks 52 %) and its
blinks drove the upper lid 2 mm through the lower one.
"""

import json

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import canonical

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.elastic.params import fit_character
from facepuppet.offline.io.obj import read_vertices_only
from facepuppet.offline.perfect_sync import evaluate
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.proposal import propose
from facepuppet.offline.perfect_sync.real_variants import MULTIPIE_TO_MEDIAPIPE, real_variants, similarity
from facepuppet.offline.perfect_sync.source import fit_kit_source
from tests.conftest import need_shared

pytestmark = pytest.mark.slow  # the ICT fit, a warp of its 53 shapes and a clone of 26k vertices

VARIANT = "mediapipe_eyes_lips_strong"


@pytest.fixture(scope="module")
def marks():
    data = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    return np.asarray(data["idx_to_landmark_verts"], np.int64)


@pytest.fixture(scope="module")
def mediapipe():
    return read_vertices_only(need_shared("mediapipe", "canonical_face_model.obj"), 468)


@pytest.fixture(scope="module")
def cloned(ict_character, marks, mediapipe):
    c = ict_character
    points = ict_control_points(marks, c.vertices, c.triangles, main_front(c))
    source = fit_character(c, points, with_muscles=False)[0]
    [(label, variant, folded)] = real_variants(c, marks, mediapipe, [VARIANT])
    target = variant.with_parts(shape_names=tuple(f"truth{i}" for i in range(variant.n_shapes)), expressions=None)
    out, report, _ = perfect_sync(target, source)
    return variant, out, report, folded


def test_the_correspondence_puts_the_mediapipe_landmarks_on_icts(ict_character, marks, mediapipe):
    """The Multi-PIE → MediaPipe table is what the variants stand on: after a similarity, each inner landmark of
    the MediaPipe face lies within a centimetre of ICT's (a wrong index lands 3-10 cm off), the mouth corners'
    on their own side."""
    a = ict_character.vertices[marks].astype(np.float64)
    b = similarity(mediapipe[list(MULTIPIE_TO_MEDIAPIPE)], a)
    off = np.linalg.norm(b - a, axis=1)
    assert off[17:].max() < 1.0 and off.max() < 2.0
    assert b[54, 0] > 0 > b[48, 0]  # the character's left is +x in both


def test_the_variant_is_a_real_change_of_proportions_not_a_fold(ict_character, cloned, marks):
    variant, _, _, folded = cloned
    assert folded == 0.0
    moved = np.linalg.norm(variant.vertices - ict_character.vertices, axis=1)
    assert moved.max() > 0.5  # cm: the lids and the lip line moved, not a rounding
    # a shape carried by the warp: the true blink still closes the (narrower) eye
    face = find_face(variant)
    points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    rest, shut = evaluate.mid_lid_gap(variant, face, points, "L", variant.dense_deltas()[
        [canonical(n) for n in variant.shape_names].index("eyeBlinkLeft")])
    assert shut < 0.2 * rest


def test_cloned_shapes_are_near_the_true_ones_on_the_held_out_head(cloned):
    variant, out, _, _ = cloned
    errs = evaluate.truth_errors(variant, out, find_face(variant))
    assert len(errs) == 51
    worst = max(errs, key=errs.get)
    # measured 13.0 % median, worst eyeLookInLeft 21 % (before: 18.0 %, worst 62 %, 6 shapes over 40 %)
    assert np.median(list(errs.values())) < 0.15, errs
    assert errs[worst] < 0.40, (worst, errs[worst])


def test_the_cloned_blinks_close_the_lids_without_tearing_through(cloned, marks):
    variant, out, _, _ = cloned
    face = find_face(variant)
    points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    lids = evaluate.lid_closure(variant, out, face, points)
    assert set(lids) == {"eyeBlinkLeft", "eyeBlinkRight"}
    for key, gap in lids.items():
        # measured 0.08 / 0.08 cm of a 0.69 cm rest gap (true 0.10); before -0.22: the upper lid 2 mm through
        assert abs(gap["cloned"]) < 0.25 * gap["rest"], (key, gap)


def test_the_cheeks_keep_their_place_between_the_found_eyes_and_mouth(ict_character, marks, mediapipe):
    """The coarse fit left the design head's cheeks (their proposed places, before each takes a skin vertex) a
    mean 0.30 cm from the true ones while its eyes and mouth were found where they are; moved by their fraction
    of the way between the eyes' and the mouth's moves (:mod:`~facepuppet.offline.perfect_sync.feature_span`),
    0.20 (the actor head of test_marker_face: 1.07 -> 0.81)."""
    source = fit_kit_source(need_shared("ict-facekit"))
    names = tuple(source.control_names)
    [(_, variant, _)] = real_variants(ict_character, marks, mediapipe, ["mediapipe"])
    _, fitted = propose(source.arrays["control_positions"], names, variant.vertices, find_face(variant))
    true = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
    v = variant.vertices.astype(np.float64)
    cheeks = [n for n in names if n.startswith("cheek")]
    assert len(cheeks) == 4
    assert np.mean([np.linalg.norm(fitted[names.index(n)] - v[true.vertex(n)]) for n in cheeks]) < 0.25
