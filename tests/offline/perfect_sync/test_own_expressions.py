"""A cloned channel is never used where the character's own VRM expression for it is measurably better (Godette):
measured on made-up clones first (hiding her drawn eye, moving otherwise), then on her real
clone, whose blinks hide her whole eye (the closed lash line too: "the eye lines break apart") where hers leave
the line, and whose brows raised at the outer end go half behind her forehead ("the brows vanish")."""

import json

import numpy as np
import pytest

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.elastic.params import fit_character
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.rig_import import import_rig
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.own_expressions import (
    CHANNEL_EXPRESSIONS,
    Drawn,
    compare,
    expression_deltas,
    prefer_own,
)
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import skin_triangles
from facepuppet.offline.perfect_sync.source import fit_kit_source
from tests.conftest import need_shared

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def godette():
    g = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    face = find_face(g)
    return g, face, find_pieces(g.vertices, face, skin_triangles(face))


def _es(g, face):
    return 0.1 * float(np.ptp(g.vertices[face.skin, 0]))


def test_a_clone_like_her_blink_is_kept_and_a_sunken_or_another_one_is_not(godette):
    g, face, pieces = godette
    own = expression_deltas(g, "Blink_L")
    assert own is not None
    es = _es(g, face)
    eye = pieces.eyes["L"][0]
    sunk = own.copy()
    sunk[eye] -= 0.3 * es * face.frame[2]  # her eye pushed back into the head: it vanishes
    other = np.zeros_like(own)
    other[eye] = -own[eye]  # opens the eye where hers closes it
    cases = (("near", 0.9 * own, "clone"), ("sunk", sunk, "Blink_L"), ("other", other, "Blink_L"))
    for label, clone, expect in cases:
        d = clone.astype(np.float32)[None].copy()
        used, _ = prefer_own(g, face, pieces, ("eyeBlinkLeft",), d, es)
        assert used["eyeBlinkLeft"]["used"].startswith(expect), (label, used)
        if expect != "clone":
            np.testing.assert_allclose(d[0], own, atol=1e-6)  # her expression in the clone's place


def test_a_defective_clone_with_nothing_to_fall_back_on_is_reported(godette):
    """A channel she has no expression for (browOuterUp) whose clone pushes a drawn brow into her head is named
    defective, with the piece and the share of it hidden; the same clone moving the brow up only is not."""
    g, face, pieces = godette
    es = _es(g, face)
    local = face.to_frame(g.vertices.astype(np.float64))
    brows = pieces.on_skin[local[pieces.on_skin, 1] > local[pieces.eyes["L"][0], 1].max()]
    assert len(brows)
    up = np.zeros((1, g.n_vertices, 3), np.float32)
    up[0, brows] = 0.05 * es * face.frame[1]
    sunk = up.copy()
    sunk[0, brows] -= 0.3 * es * face.frame[2]
    _, defective = prefer_own(g, face, pieces, ("browOuterUpLeft",), sunk, es)
    assert "browOuterUpLeft" in defective and "goes behind the skin" in defective["browOuterUpLeft"][0], defective
    _, defective = prefer_own(g, face, pieces, ("browOuterUpLeft",), up, es)
    assert defective == {}, defective


def test_her_own_expressions_are_no_worse_than_themselves(godette):
    """The choice is not circular: each expression measured against itself is not worse."""
    g, face, pieces = godette
    drawn = Drawn(g, face, pieces, _es(g, face))
    for preset in CHANNEL_EXPRESSIONS.values():
        own = expression_deltas(g, preset)
        assert compare(drawn, face.mesh, own, own)["worse"] == [], preset


@pytest.mark.slow
def test_godette_perfect_sync_uses_her_own_where_the_clone_is_worse_and_says_which(godette):
    kit = need_shared("ict-facekit")
    ict = import_rig(kit / "generic_neutral_mesh.obj", kit)
    marks = json.loads((kit / "vertex_indices.json").read_text(encoding="utf-8"))
    points = ict_control_points(marks["idx_to_landmark_verts"], ict.vertices, ict.triangles, main_front(ict))
    source = fit_character(ict, points, with_muscles=False)[0]
    g, face, pieces = godette
    out, report, _ = perfect_sync(g, source, prefer_own=True)  # as the command does
    used = report["own_expressions"]
    assert set(used) == set(CHANNEL_EXPRESSIONS)  # she has every one of them
    dense = out.dense_deltas()
    drawn = Drawn(g, face, pieces, _es(g, face))
    for key, d in used.items():
        own = expression_deltas(g, CHANNEL_EXPRESSIONS[key])
        shape = dense[out.shape_names.index(key)].astype(np.float64)
        if d["used"] == "clone":
            assert compare(drawn, face.mesh, shape, own)["worse"] == [], (key, d)  # kept only where not worse
        else:
            np.testing.assert_allclose(shape, own, atol=1e-5)
    # measured: her blinks leave the closed lash line where the clones hide her whole eye; her O and U move her
    # drawn mouth otherwise than the clones (cosines -0.04 and -0.39)
    for key in ("eyeBlinkLeft", "eyeBlinkRight", "mouthFunnel", "mouthPucker"):
        assert not used[key]["used"].startswith("clone"), (key, used[key])
    # the outer brow raises hid half of her brows (reported defective, with no expression of hers to fall back
    # on) until her drawn pieces kept their height over her still skin (:mod:`.skin_clearance`): none hides a
    # piece now; a defective shape is still reported (test_a_defective_clone_with_nothing_to_fall_back_on_is_
    # reported), and her folded mouth is (test_her_folded_mouth_is_reported)
    assert not [d for d in report["defective_shapes"] if "goes behind" in d["why"]], report["defective_shapes"]
    # measured: no channel she has an expression for folds a piece in its clone beyond the expression's
    assert all(v["folded_clone"] <= v["folded_own"] + 0.15 for v in used.values()), used


@pytest.mark.slow
def test_her_folded_mouth_is_reported(godette):
    """Her clone's mouthClose and mouthShrugLower turn the small drawn piece at her upper inner lip over (79 % of
    its front-view area measured; the check counted only hidden pieces, so it said "no defective shapes"): with
    no expression of hers for them, both are reported defective for folding."""
    g, _, _ = godette
    source = fit_kit_source(need_shared("ict-facekit"))
    _, report, _ = perfect_sync(g, source, prefer_own=True)
    folds = {d["shape"]: d["why"] for d in report["defective_shapes"] if "folds over" in d["why"]}
    assert {"mouthClose", "mouthShrugLower"} <= set(folds), report["defective_shapes"]
    assert not set(folds) & set(CHANNEL_EXPRESSIONS)  # where she has her own, it is used instead


def test_the_command_prefers_her_own_and_says_so(tmp_path):
    """The real command on Godette: her own blinks, O and U, and a line per channel saying which was used."""
    import os
    import subprocess
    import sys

    kit = need_shared("ict-facekit").parent
    env = {**os.environ, "FACEPUPPET_DATA": str(kit), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    exe = [sys.executable, "-m", "facepuppet"]
    subprocess.run(exe + ["import-rig", str(kit / "gltf" / "Godette_vrm_v4.vrm"), "-o", str(tmp_path / "g.npz")],
                   check=True, env=env, capture_output=True)
    run = subprocess.run(exe + ["perfect-sync", str(tmp_path / "g.npz"), "-o", str(tmp_path / "ps.npz")], env=env,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    for key, preset in (("eyeBlinkLeft", "Blink_L"), ("mouthFunnel", "O"), ("mouthPucker", "U")):
        assert any(line.startswith(f"{key}: {preset} (the character's own): the clone is worse") for line in lines)
    assert any(line.startswith("jawOpen: clone: no worse") for line in lines), lines
    defective = [line for line in lines if line.startswith("defective:")]
    assert not [line for line in defective if "goes behind" in line], lines  # her brows no longer vanish
    # her folded mouth is said, with no expression of hers to fall back on (test_her_folded_mouth_is_reported)
    assert any(line.startswith("defective: mouthClose:") and "folds over" in line for line in defective), lines
    assert all("no expression of the character's to fall back on" in line for line in defective), lines


def test_a_drawn_piece_folded_over_is_defective_and_makes_a_clone_worse(godette):
    """A clone that turns a drawn piece over (its triangles' front-view winding flips: a brow mirrored across
    itself) is named defective with the share folded; the same brow slid sideways is not. Where she has her own
    expression, a clone that folds a piece her expression does not fold is worse and hers is used."""
    g, face, pieces = godette
    es = _es(g, face)
    local = face.to_frame(g.vertices.astype(np.float64))
    brows = pieces.on_skin[local[pieces.on_skin, 1] > local[pieces.eyes["L"][0], 1].max()]
    drawn = Drawn(g, face, pieces, es)
    [label] = np.unique(pieces.labels[brows[local[brows, 0] > 0]])  # her left brow: one drawn piece
    brows = np.unique(drawn.triangles[drawn.piece == label])  # every copy of its vertices along its seams
    centre = local[brows, 0].mean()
    slid = np.zeros((1, g.n_vertices, 3), np.float32)
    slid[0, brows] = 0.05 * es * face.frame[0]
    folded = np.zeros((1, g.n_vertices, 3), np.float32)
    folded[0, brows] = (2 * (centre - local[brows, 0]))[:, None] * face.frame[0]  # mirrored across its middle
    assert max(drawn.folding(folded[0].astype(np.float64)).values()) > 0.9
    assert drawn.folding(slid[0].astype(np.float64)) == {}
    _, defective = prefer_own(g, face, pieces, ("browOuterUpLeft",), folded, es)
    assert "browOuterUpLeft" in defective and any("folds over" in w for w in defective["browOuterUpLeft"]), defective
    _, defective = prefer_own(g, face, pieces, ("browOuterUpLeft",), slid, es)
    assert defective == {}, defective
    own = expression_deltas(g, "Blink_L")
    clone = own.astype(np.float32)[None].copy()
    clone[0, brows] += folded[0, brows]
    used, _ = prefer_own(g, face, pieces, ("eyeBlinkLeft",), clone, es)
    assert used["eyeBlinkLeft"]["used"].startswith("Blink_L") and "folds over" in used["eyeBlinkLeft"]["why"], used
