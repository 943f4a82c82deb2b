"""Detail transfer onto the ICT head (Ju & Lee §5.2): placement, interpolation, locality, no linear term."""

import json

import numpy as np
import pytest

from facepuppet.offline.gestures.detail_transfer import (
    DetailTransfer,
    detail_character,
    marker_detail,
    marker_region,
    place_markers,
)
from facepuppet.offline.io.capture import read_c3d
from tests.conftest import need_shared


@pytest.fixture(scope="module")
def placed(ict_character):
    take = read_c3d(need_shared("markers", "animface_jaw.c3d"))
    marks = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text())["idx_to_landmark_verts"]
    placement = place_markers(take.markers[0], take.names, ict_character, marks)
    return take, placement, DetailTransfer(placement, ict_character)


def test_markers_land_on_the_face_by_landmarks(placed, ict_character):
    take, pl, _ = placed
    assert pl.rms < 1.5 and 0.5 < pl.scale < 2.0  # cm, ICT units
    v = ict_character.vertices
    left, right = take.names.index("Leyebrow_M"), take.names.index("Reyebrow_M")
    assert v[pl.vertices[left], 0] > 2 > -2 > v[pl.vertices[right], 0]       # x = the character's left
    assert v[pl.vertices[take.names.index("Chin")], 1] < v[pl.vertices[take.names.index("NoseHead")], 1]


def test_one_marker_moves_its_surface_point_by_the_same_amount_and_nothing_outside(placed, ict_character):
    take, pl, tr = placed
    i = take.names.index("Leyebrow_M")
    d = np.zeros((len(take.names), 3))
    d[i] = [0.0, 0.3, 0.1]
    out = tr.transfer(d)
    expected = pl.similarity[:3, :3] @ d[i]                     # marker units -> character units and axes
    np.testing.assert_allclose(out[pl.vertices[i]], expected, atol=1e-9)   # the RBF interpolates
    moved = np.linalg.norm(out, axis=1) > 0
    assert set(tr.vertex_region[moved]) == {"brows"}           # brow markers move only brow vertices
    far = np.linalg.norm(ict_character.vertices[:, None] - pl.surface[tr.regions == "brows"][None], axis=2)
    assert not moved[far.min(1) >= tr.radius["brows"]].any()    # compact support
    assert moved.sum() > 20


def test_no_linear_term_a_constant_shift_does_not_reach_beyond_the_support(placed, ict_character):
    take, pl, tr = placed
    lips = tr.regions == "lips"
    d = np.zeros((len(take.names), 3))
    d[lips] = [0.0, -0.5, 0.0]
    out = tr.transfer(d)
    np.testing.assert_allclose(out[pl.vertices[lips]], np.broadcast_to(pl.similarity[:3, :3] @ d[lips][0],
                                                                       (lips.sum(), 3)), atol=1e-9)
    region = np.flatnonzero(tr.vertex_region == "lips")
    dist = np.linalg.norm(ict_character.vertices[region, None] - pl.surface[lips][None], axis=2).min(1)
    beyond = region[dist >= tr.radius["lips"]]
    assert len(beyond) > 0 and np.all(out[beyond] == 0.0)     # a linear (or constant) term would move them


def test_detail_features_become_extra_shapes(placed, ict_character):
    take, pl, tr = placed
    det = marker_detail([take.markers[:240]], take.names, per_region=1, window=11, step=2)
    assert det.feature_names == ("detail_brows_0", "detail_eyes_0", "detail_lips_0", "detail_rest_0")
    for name, direction in zip(det.feature_names, det.directions):
        outside = np.array([marker_region(n) != name.split("_")[1] for n in take.names])
        assert np.all(direction[outside] == 0.0) and np.abs(direction[~outside]).max() > 0
    np.testing.assert_allclose(det.tracks[0][::2].std(0), 1.0, rtol=0.05)  # z-scored on the fitted frames
    char = detail_character(ict_character, tr, det)
    assert char.shape_names[-4:] == det.feature_names and char.n_shapes == ict_character.n_shapes + 4
    dense = char.dense_deltas()[-4:]
    np.testing.assert_allclose(dense, tr.transfer(det.directions), atol=1e-5)
    with pytest.raises(ValueError, match="already has"):
        detail_character(char, tr, det)


def test_bad_inputs_are_refused(placed, ict_character):
    take, pl, tr = placed
    with pytest.raises(ValueError, match="at least 3 markers with a landmark"):
        place_markers(np.zeros((3, 3)), ["a", "b", "c"], ict_character, np.zeros(68, int))
    with pytest.raises(ValueError, match="landmarks: expected 68"):
        place_markers(take.markers[0], take.names, ict_character, np.zeros(5, int))
    with pytest.raises(ValueError, match="displacements"):
        tr.transfer(np.zeros((3, 3)))


def test_detail_table_aligns_marker_tracks_with_the_database_frames(tmp_path):
    from facepuppet.runtime.files.tables import save_tables
    from facepuppet.runtime.gestures.layer import GROUPS, load_gesture_db

    from facepuppet.offline.gestures.detail_transfer import MarkerDetail, detail_table

    n = [40, 30]
    arrays = {"intensity": np.zeros(70, np.float32), "features": np.zeros((70, 1), np.float32),
              "feature_group": np.array([GROUPS.index("head")], np.int32), "feature_scale": np.ones(1, np.float32),
              "blend_basis": np.zeros((0, 1), np.float32), "frame_take": np.repeat([0, 1], n).astype(np.int32),
              "available": np.ones((70, 6), bool)}
    save_tables(tmp_path / "g.npz", "gesture_db", arrays, channels={"features": ["headYaw"], "takes": ["a", "jaw"],
                                                                     "groups": list(GROUPS)}, settings={"fps": 30.0})
    db = load_gesture_db(tmp_path / "g.npz")
    track = np.arange(60.0)[:, None]                     # 60 Hz: value = frame index at 60 Hz
    det = MarkerDetail(("m",), np.zeros((1, 3)), ("detail_rest_0",), np.zeros((1, 1, 3)), [track], 0.0)
    table = detail_table(db, det, ["jaw"])
    assert np.all(table[:40] == 0.0)
    np.testing.assert_allclose(table[40:, 0], np.minimum(2.0 * np.arange(30), 59.0))  # 30 fps row j = 60 Hz 2j
    with pytest.raises(ValueError, match="not a take of the database"):
        detail_table(db, det, ["cheeks"])
