"""A cloned channel is never used where the character's own VRM expression for it is measurably better (Godette):
measured on made-up clones first (torn, hiding her drawn features, moving otherwise), then on her real clone."""

import numpy as np
import pytest

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.own_expressions import (
    CHANNEL_EXPRESSIONS,
    expression_deltas,
    measure,
    prefer_own,
    verdict,
)
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import skin_triangles
from tests.conftest import need_shared

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def godette():
    g = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    face = find_face(g)
    return g, face, find_pieces(g.vertices, face, skin_triangles(face))


def _es(g, face):
    return 0.1 * float(np.ptp(g.vertices[face.skin, 0]))


def test_a_clone_like_her_blink_is_kept_and_a_torn_or_sunken_one_is_not(godette):
    g, face, pieces = godette
    own = expression_deltas(g, "Blink_L")
    assert own is not None
    es = _es(g, face)
    near_own = 0.9 * own  # a little shy of her blink: no worse by any measure
    torn = own.copy()
    lash = pieces.eyes["L"][0]
    torn[lash[::7]] += 0.8 * es * face.frame[1]  # every 7th vertex of her left eye's pieces pulled up: torn lines
    sunk = own.copy()
    sunk[pieces.eyes["L"][0]] -= 0.3 * es * face.frame[2]  # her eye pushed back into the head: it vanishes
    for clone, expect in ((near_own, "clone"), (torn, "Blink_L"), (sunk, "Blink_L")):
        d = clone.astype(np.float32)[None].copy()
        report = prefer_own(g, face, pieces, ("eyeBlinkLeft",), d, es)
        assert report["eyeBlinkLeft"]["used"].startswith(expect), report
        if expect != "clone":
            np.testing.assert_allclose(d[0], own, atol=1e-6)  # her expression in the clone's place


@pytest.mark.slow
def test_godette_perfect_sync_reports_per_channel_which_was_used(godette, tmp_path):
    import json

    from facepuppet.offline.elastic.commands import main_front
    from facepuppet.offline.elastic.control_points import ict_control_points
    from facepuppet.offline.elastic.params import fit_character
    from facepuppet.offline.io.rig_import import import_rig
    from facepuppet.offline.perfect_sync.commands import perfect_sync

    kit = need_shared("ict-facekit")
    ict = import_rig(kit / "generic_neutral_mesh.obj", kit)
    marks = json.loads((kit / "vertex_indices.json").read_text(encoding="utf-8"))
    points = ict_control_points(marks["idx_to_landmark_verts"], ict.vertices, ict.triangles, main_front(ict))
    source = fit_character(ict, points, with_muscles=False)[0]
    g, face, _ = godette
    out, report, _ = perfect_sync(g, source)
    used = report["own_expressions"]
    assert set(used) == set(CHANNEL_EXPRESSIONS)  # she has every one of them
    dense = out.dense_deltas()
    for key, d in used.items():
        own = expression_deltas(g, CHANNEL_EXPRESSIONS[key])
        shape = dense[out.shape_names.index(key)]
        if d["used"] == "clone":
            assert verdict(d) == [], (key, d)  # kept only where no measure says it is worse
        else:
            np.testing.assert_allclose(shape, own, atol=1e-5)
            # and her expression is no worse than itself by the same measures (the choice is not circular)
            assert verdict(measure(g, face, np.zeros(0, np.int64), own, own, _es(g, face))) == []
    # measured: her O and U move her drawn mouth otherwise than the clones (cosines -0.04 and -0.39)
    assert used["mouthFunnel"]["used"].startswith("O") and used["mouthPucker"]["used"].startswith("U")
