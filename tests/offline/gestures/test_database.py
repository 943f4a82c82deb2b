"""Gesture database from the real takes, the synthesize command, and the --input audio run option."""

import argparse

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.gestures.tables import GROUPS, load_gesture_db
from facepuppet.runtime.recording.replay_source import open_recording

from facepuppet.offline.gestures import commands as gesture_commands
from facepuppet.offline.gestures.database import build_gesture_db, quantile_map
from facepuppet.offline.gestures.regional_features import head_track, split_regions
from tests.conftest import need_shared


@pytest.fixture(scope="module")
def db_path(tmp_path_factory):
    d = need_shared()
    out = tmp_path_factory.mktemp("gdb") / "g.npz"
    build_gesture_db(out, (d / "speech/facegood_1114_3_15.wav", d / "speech/facegood_1114_3_15_blendshapes.csv",
                           d / "speech/facegood_to_arkit.csv"),
                     llf=[d / "tracker/livelinkface_myslate_3.csv"], markers=[d / "markers/animface_jaw.c3d"])
    return out


@pytest.mark.data
def test_real_database_has_each_group_from_its_take(db_path):
    db = load_gesture_db(db_path)
    names = db.channels["features"]
    assert db.channels["takes"] == ["facegood_1114_3_15_blendshapes", "livelinkface_myslate_3", "animface_jaw"]
    assert len(db["intensity"]) == 1472 + 164 + 795
    avail = db["available"]
    assert avail[:1472, GROUPS.index("lips")].all() and not avail[:1472, GROUPS.index("eyes")].any()
    assert avail[1472:1636, GROUPS.index("eyes")].all() and avail[1636:, GROUPS.index("head")].all()
    jaw = np.asarray(db["features"])[:1472, names.index("jawOpen")]
    assert np.corrcoef(jaw, db["intensity"][:1472])[0, 1] > 0.4  # the voice opens the jaw
    # the stochastic columns come by region, then name (not in a set's hash order, which changes per process)
    stoch = [n for n in names if db["feature_group"][names.index(n)] in
             [GROUPS.index(g) for g in ("brows", "eyes", "rest")]]
    assert stoch == sorted(stoch, key=lambda n: (db["feature_group"][names.index(n)], n))


@pytest.mark.data
def test_synthesize_command_writes_a_replayable_session(db_path, tmp_path):
    wav = need_shared("speech", "arctic_a0007.wav")
    parser = argparse.ArgumentParser()
    gesture_commands.register(parser.add_subparsers())
    args = parser.parse_args(["synthesize-gestures", str(db_path), str(wav), "-o", str(tmp_path / "s.fps"),
                              "--seed", "2", "--pictures", str(tmp_path / "pics")])
    assert args.func(args) == 0
    frames = open_recording(tmp_path / "s.fps")
    assert len(frames) == 120 and "jawOpen" in frames[0].channels and frames[0].head_rotation is not None
    assert (tmp_path / "pics" / "gestures.png").stat().st_size > 1000


def test_style_parsing():
    assert gesture_commands.parse_style("brows=a, head=b") == {"brows": "a", "head": "b"}
    with pytest.raises(ValueError, match="GROUP=TAKE"):
        gesture_commands.parse_style("brows")


def test_regions_partition_the_channels_and_head_track_is_rigid():
    regions = split_regions(["EyeBlinkLeft", "browInnerUp", "jawOpen", "cheekPuff", "mouthClose"])
    assert {k: list(v) for k, v in regions.items()} == {"brows": [1], "eyes": [0], "lips": [2, 4], "rest": [3]}
    names = ["ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop"]
    base = np.array([[0, 10, 0], [3, 9, 0], [-3, 9, 0], [0, 6, 3]], float)
    yaw = 0.1
    R = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    track = head_track(np.stack([base, base @ R.T + [1, 2, 3]]), names)
    c = base.mean(0)
    np.testing.assert_allclose(track[1], [yaw, 0, 0, *(R @ c + [1, 2, 3] - c)], atol=1e-9)


def test_quantile_map_keeps_order_and_takes_the_reference_distribution():
    x = np.array([3.0, 1.0, 2.0])
    y = quantile_map(x, np.array([10.0, 20.0, 30.0]))
    assert y[1] < y[2] < y[0]
    assert 10.0 <= y.min() and y.max() <= 30.0


def test_run_input_audio_needs_gestures_and_audio():
    from facepuppet.runtime.commands.run import run_live

    args = argparse.Namespace(input="audio", gestures=None, audio=None, audio_file=None, size="64x64", fps=30.0,
                              duration=1.0, listen=None, allow=None, vmc_out=None, config=None, character="x")
    with pytest.raises(ValueError, match="--input audio"):
        run_live(args)


@pytest.mark.slow
@pytest.mark.data
def test_transfer_detail_writes_a_character_with_local_detail_shapes_and_gesture_tables(db_path, ict_character_path,
                                                                                       tmp_path, capsys):
    from facepuppet.runtime.gestures.layer import gesture_layer
    from facepuppet.runtime.model.character import Character

    ict = need_shared("ict-facekit")
    parser = argparse.ArgumentParser()
    gesture_commands.register(parser.add_subparsers())
    out, g_out = tmp_path / "detail.npz", tmp_path / "g_detail.npz"
    args = parser.parse_args(["transfer-detail", str(ict_character_path), "--markers",
                              str(need_shared("markers", "animface_jaw.c3d")), "--landmarks",
                              str(ict / "vertex_indices.json"), "-o", str(out), "--per-region", "1", "--step", "4",
                              "--window", "11", "--gestures", str(db_path), "--gestures-out", str(g_out)])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    assert "[4/4] 4 detail shapes added" in text and "detail_lips_0:" in text
    base, char = Character.load(ict_character_path), Character.load(out)
    names = ("detail_brows_0", "detail_eyes_0", "detail_lips_0", "detail_rest_0")
    assert char.shape_names == base.shape_names + names
    dense = char.dense_deltas()
    np.testing.assert_array_equal(dense[:base.n_shapes], base.dense_deltas())   # the rig's own shapes kept
    moved = np.linalg.norm(dense[base.n_shapes:], axis=2) > 1e-5
    assert moved.any(1).all()
    centre = {n: base.vertices[m].mean(0) for n, m in zip(names, moved)}
    assert centre["detail_brows_0"][1] > centre["detail_eyes_0"][1] > centre["detail_lips_0"][1]  # y up
    z = base.vertices[:, 2]                                   # the head spans z -9.2 .. 13.1 cm; the face looks +z
    assert base.vertices[moved.any(0), 2].min() > z.min() + 0.3 * np.ptp(z)   # front of the head only, never the back
    layer = gesture_layer(g_out, voice_only=True, log=lambda *_: None)
    frame = layer(None, 0.0)
    assert frame.channels[-4:] == names
    with pytest.raises(ValueError, match="exists; pass --force"):
        args.func(args)
    # a later argument that is wrong (--gestures names a character, not gesture tables): nothing is written
    out2, g_out2 = tmp_path / "detail2.npz", tmp_path / "g_detail2.npz"
    bad = parser.parse_args(["transfer-detail", str(ict_character_path), "--markers",
                             str(need_shared("markers", "animface_jaw.c3d")), "--landmarks",
                             str(ict / "vertex_indices.json"), "-o", str(out2), "--per-region", "1", "--step", "4",
                             "--window", "11", "--gestures", str(ict_character_path), "--gestures-out", str(g_out2)])
    with pytest.raises(TablesError, match="gesture_db"):
        bad.func(bad)
    assert not out2.exists() and not g_out2.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]    # no temporary file left


@pytest.mark.gl
def test_detail_contact_sheet_tints_where_each_shape_acts(ict_character_path):
    from facepuppet.runtime.model.character import Character

    char = Character.load(ict_character_path)
    rows = {}
    for shape in ("jawOpen", "browDown_L"):   # each on its own sheet: the tint scale is common to a sheet
        sheet = gesture_commands.render_detail_sheet(char, [shape], weight=1.0, cell=(96, 96), columns=2)
        assert sheet.shape[1] == 2 * 96
        neutral, cell = (sheet[:96, k * 96:(k + 1) * 96].astype(int) for k in range(2))
        tint = (cell[..., 0] - cell[..., 1]) - (neutral[..., 0] - neutral[..., 1]) > 40   # redder than neutral
        assert tint.sum() > 20, shape
        rows[shape] = np.flatnonzero(tint.any(1)).mean()
    assert rows["jawOpen"] > 48 > rows["browDown_L"], rows     # the jaw in the lower half, the brow above


def test_landmarks_json_is_checked(tmp_path):
    bad = tmp_path / "lm.json"
    bad.write_text("[1, 2, 3]")
    with pytest.raises(ValueError, match="expected 68 integer vertex indices"):
        gesture_commands.load_landmarks(bad)
    bad.write_text('{"idx_to_landmark_verts": ' + str(list(range(68))) + "}")
    assert gesture_commands.load_landmarks(bad).shape == (68,)
