"""The kernel-PLS runtime stage: per-frame path against a plain reference, tables round trip, replay."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError, load_tables, save_tables
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.kpls.stage import KplsRetarget

from helpers.kpls_stages import random_stage
from helpers.logs import logged


def _reference(stage, w):
    """Eq. 10 with the centred kernel row written out by loops, float64."""
    x = stage.source_features.astype(np.float64) @ w
    X = stage.train_inputs.astype(np.float64)
    k = []
    for xi in X:
        if stage.kernel == "rbf":
            k.append(np.exp(-stage.gamma * ((x - xi) ** 2).sum()))
        elif stage.kernel == "poly":
            k.append((stage.gamma * x @ xi + stage.coef0) ** stage.degree)
        else:
            k.append(x @ xi)
    k = np.array(k)
    kc = k - stage.kernel_col_mean - k.mean() + stage.kernel_grand_mean
    return kc @ stage.dual_coef.astype(np.float64) + stage.target_mean


@pytest.mark.parametrize("kernel", ["rbf", "poly", "linear"])
def test_per_frame_path_matches_the_plain_reference(kernel):
    stage = random_stage(kernel)
    rng = np.random.default_rng(1)
    for _ in range(5):
        w = rng.uniform(0, 1, 3)
        got = stage.predict_weights(w)
        assert got.dtype == np.float32 and got.shape == (4,)
        np.testing.assert_allclose(got, _reference(stage, w), rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("kernel", ["rbf", "poly", "linear"])
def test_apply_with_its_folded_channel_map_matches_the_plain_reference(kernel):
    # the linear kernel's eq. 10 folds into one (n_target, n_channels) matrix per channel tuple
    stage = random_stage(kernel)
    rng = np.random.default_rng(2)
    for _ in range(5):
        w = rng.uniform(0, 1, 3)
        frame = Frame(t=0.0, channels=("eyeBlinkRight", "jawOpen", "eyeBlinkLeft"),
                      weights=w[[2, 0, 1]].astype(np.float32))
        got = stage.apply(frame)
        assert got.dtype == np.float32 and got.shape == (4,)
        np.testing.assert_allclose(got, _reference(stage, w), rtol=1e-4, atol=1e-4)


def test_apply_maps_frame_channels_by_name_and_skips_frames_without_weights():
    stage = random_stage()
    w = np.array([0.3, 0.8, 0.1], np.float32)
    # Live Link spelling, another order, an extra channel and a NaN (missing = 0)
    frame = Frame(t=0.0, channels=("EyeBlinkRight", "JawOpen", "TongueOut", "EyeBlinkLeft"),
                  weights=np.array([0.1, 0.3, 0.5, 0.8], np.float32))
    np.testing.assert_allclose(stage.apply(frame), stage.predict_weights(w), rtol=1e-6)
    nan_frame = Frame(t=0.0, channels=("JawOpen", "EyeBlinkLeft"), weights=np.array([0.3, np.nan], np.float32))
    np.testing.assert_allclose(stage.apply(nan_frame), stage.predict_weights([0.3, 0.0, 0.0]), rtol=1e-6)
    assert stage.apply(Frame(t=0.0)) is None


def test_tables_round_trip_and_damaged_files(tmp_path):
    stage = random_stage("poly")
    path = stage.save(tmp_path / "r.npz")
    back = KplsRetarget.load(path)
    assert back.kernel == "poly" and back.source_names == stage.source_names and back.units == "cm"
    w = np.array([0.2, 0.5, 0.9])
    # gamma and coef0 are float32 in the file: equal to float32 rounding
    np.testing.assert_allclose(back.predict_weights(w), stage.predict_weights(w), rtol=1e-6)
    again = KplsRetarget.load(back.save(tmp_path / "again.npz"))
    assert again.predict_weights(w).tobytes() == back.predict_weights(w).tobytes()
    t = load_tables(path)
    arrays = dict(t.arrays)
    arrays["kernel_params"] = np.array([7, 0.05, 1, 2], np.float32)
    save_tables(tmp_path / "bad.npz", "retarget_kpls", arrays, channels=dict(t.channels))
    with pytest.raises(TablesError, match="bad.npz: kernel_params: kernel code must be 0, 1 or 2"):
        KplsRetarget.load(tmp_path / "bad.npz")
    arrays = dict(t.arrays)
    arrays["dual_coef"] = arrays["dual_coef"][:, :3]
    with pytest.raises(TablesError, match="dual_coef"):
        save_tables(tmp_path / "bad2.npz", "retarget_kpls", arrays, channels=dict(t.channels))


def test_replay_command_uses_the_retarget(tmp_path, egl_ctx):
    from facepuppet.runtime.commands.replay import register, run_replay
    from facepuppet.runtime.demo.head import build_demo_character

    character = build_demo_character()
    char_path = character.save(tmp_path / "demo.npz")
    stage = random_stage(target=character.shape_names, source=("jawOpen", "mouthSmileLeft"))
    stage.save(tmp_path / "r.npz")
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    wrong = random_stage().save(tmp_path / "wrong.npz")
    session = tmp_path / "take.csv"
    session.write_text("Timecode,BlendShapeCount,JawOpen,MouthSmileLeft\n"
                       "00:00:00:00.000,2,0.1,0.2\n00:00:00:01.000,2,0.6,0.4\n")
    logs = []
    args = parser.parse_args(["replay", str(session), "-c", str(char_path), "--headless", "--size", "64x48",
                              "--retarget", str(tmp_path / "r.npz"), "--path", "cpu"])
    with logged(logs):
        assert run_replay(args) == 0
    assert any("retarget" in line and "rbf kernel" in line for line in logs)
    args.retarget = wrong
    with pytest.raises(ValueError, match="its target shapes \\(4\\) are not the shapes of"):
        with logged(logs):
            run_replay(args)
