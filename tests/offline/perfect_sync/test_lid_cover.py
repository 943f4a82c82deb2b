"""A closed lid covers the eye over its whole length, measured from the front (:mod:`.lid_cover`).

The measure must pass ICT's own true blinks (they close cleanly; their shadow mesh shows along the lid line)
and fail a blink that leaves the eye showing: the lids stopped half way, or the lid closed while the eye's tear
film and shadow mesh stayed where they were (what a cloned ICT blink did: the pieces lying on the eyeball poked
through the closed lid as dark pinholes).
"""

import json

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import canonical

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.lid_cover import ALLOWED, EyeCover, blink_cover, open_blinks
from tests.conftest import need_shared


@pytest.fixture(scope="module")
def ict_cover(ict_character):
    data = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    marks = np.asarray(data["idx_to_landmark_verts"], np.int64)
    c = ict_character
    face = find_face(c)
    points = ict_control_points(marks, c.vertices, c.triangles, main_front(c))
    keys = [canonical(n) for n in c.shape_names]
    dense = c.dense_deltas()
    blinks = np.stack([dense[keys.index("eyeBlinkLeft")], dense[keys.index("eyeBlinkRight")]])
    return EyeCover(c.vertices, face, points), face, blinks


def test_the_true_blinks_cover_the_eye_and_a_blink_that_leaves_it_showing_is_named(ict_cover):
    cover, face, blinks = ict_cover
    assert set(cover.eyes) == {"L", "R"}
    names = ["eyeBlinkLeft", "eyeBlinkRight"]
    true = blink_cover(cover, names, blinks)
    assert set(true) == set(names)
    for key, c in true.items():
        assert c["fraction"] <= ALLOWED and c["opening_pixels"] > 1000, (key, c)
    assert open_blinks(true) == []
    # at rest the opening shows the eye (all but the lids' rounded rims, which the depth valley takes in: 89 %)
    rest = cover.showing("L", np.zeros_like(blinks[0]))
    assert rest["fraction"] > 0.8
    # the lids stopped half way: a slit along the whole eye
    half = blink_cover(cover, names, 0.5 * blinks)
    assert all(c["fraction"] > 0.1 for c in half.values()), half
    assert [d["shape"] for d in open_blinks(half)] == names
    # the lid closes, the pieces on the eyeball (not skin) stay: they come through the closed lid
    still = blinks.copy()
    still[:, np.setdiff1d(face.mesh, face.skin)] = 0.0
    poked = blink_cover(cover, names, still)
    assert all(c["fraction"] > ALLOWED and c["eye"] > 0 for c in poked.values()), poked
    [left, right] = open_blinks(poked)
    assert left["shape"] == "eyeBlinkLeft" and "the eye's pieces" in left["why"]
