"""Gesture database from the real takes, the synthesize command, and the --input audio run option."""

import argparse

import numpy as np
import pytest

from facepuppet.offline import gesture_commands
from facepuppet.offline.gesture_db import build_gesture_db, quantile_map
from facepuppet.offline.regional_features import head_track, split_regions
from facepuppet.runtime.gestures import GROUPS, load_gesture_db
from facepuppet.runtime.sources import open_recording
from tests.conftest import need_shared


@pytest.fixture(scope="module")
def db_path(tmp_path_factory):
    d = need_shared()
    out = tmp_path_factory.mktemp("gdb") / "g.npz"
    build_gesture_db(out, (d / "speech/facegood_1114_3_15.wav", d / "speech/facegood_1114_3_15_blendshapes.csv",
                           d / "speech/facegood_to_arkit.csv"),
                     llf=[d / "tracker/livelinkface_myslate_3.csv"], markers=[d / "markers/animface_jaw.c3d"])
    return out


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
    from facepuppet.runtime.run import run_live

    args = argparse.Namespace(input="audio", gestures=None, audio=None, audio_file=None, size="64x64", fps=30.0,
                              duration=1.0, listen=None, allow=None, vmc_out=None, config=None, character="x")
    with pytest.raises(ValueError, match="--input audio"):
        run_live(args)
