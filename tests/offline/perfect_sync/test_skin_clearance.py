"""A decal face's drawn pieces slide over its still skin, never into it (Godette).

Measured on Godette's clone before the clearance: 11 cloned shapes reported defective, each hiding a third to
two thirds of a drawn piece behind her skin (mouthClose, the smiles, the lip rolls, mouthUpperUp and noseSneer
her drawn mouth; browOuterUp her brows, 50 %); after it, none.
"""

import numpy as np
import pytest

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.own_expressions import CHANNEL_EXPRESSIONS, Drawn
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import skin_triangles
from facepuppet.offline.perfect_sync.skin_clearance import keep_clearance
from facepuppet.offline.perfect_sync.source import fit_kit_source
from tests.conftest import need_shared

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def godette():
    g = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    face = find_face(g)
    return g, face, find_pieces(g.vertices, face, skin_triangles(face))


def test_a_piece_pushed_into_the_skin_is_raised_and_keeps_its_motion_across(godette):
    g, face, pieces = godette
    es = 0.1 * float(np.ptp(g.vertices[face.skin, 0]))
    drawn = Drawn(g, face, pieces, es)
    moved = np.concatenate([pieces.feature_vertices, pieces.on_skin])
    d = np.zeros((2, g.n_vertices, 3), np.float32)
    across = 0.05 * es * face.frame[1] + 0.03 * es * face.frame[0]
    d[0, moved] = across - 0.3 * es * face.frame[2]  # up and sideways, and back into the head
    d[1, moved] = 0.1 * es * face.frame[2]  # forward, no further from the skin than it was: nothing to raise
    before = d.copy()
    assert max(drawn.vanishing(d[0].astype(np.float64)).values()) > 0.5  # the measure sees it go
    raised = keep_clearance(d, g.vertices, face, moved, skin_triangles(face))
    assert raised > 0
    assert max(drawn.vanishing(d[0].astype(np.float64)).values(), default=0.0) < 0.05
    np.testing.assert_array_equal(d[1], before[1])  # forward of its rest height: left as it was
    for axis in (0, 1):  # the motion across the face is the field's
        np.testing.assert_allclose(d[0, moved] @ face.frame[axis], before[0, moved] @ face.frame[axis], atol=1e-5)
    assert np.all(d[0, moved] @ face.frame[2] >= before[0, moved] @ face.frame[2] - 1e-6)  # only ever raised


@pytest.mark.slow
def test_godettes_clone_hides_none_of_her_drawn_pieces(godette):
    g, _, _ = godette
    source = fit_kit_source(need_shared("ict-facekit"))
    _, report, _ = perfect_sync(g, source, prefer_own=True)
    # before: 11 shapes defective, each hiding a drawn piece; none hides one now (what is still reported is a
    # piece folding over: :func:`test_own_expressions.test_her_folded_mouth_is_reported`)
    assert not [d for d in report["defective_shapes"] if "goes behind" in d["why"]], report["defective_shapes"]
    used = report["own_expressions"]
    assert set(used) == set(CHANNEL_EXPRESSIONS)
    for key in ("eyeBlinkLeft", "eyeBlinkRight", "mouthFunnel", "mouthPucker"):  # her own still, as before
        assert not used[key]["used"].startswith("clone"), (key, used[key])
    assert used["jawOpen"]["used"] == "clone" and used["jawOpen"]["cosine"] >= 0.7
