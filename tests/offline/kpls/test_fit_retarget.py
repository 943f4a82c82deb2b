"""fit-retarget with its defaults: finite cross-validation, identity on the identical character, range and
timing kept onto a variant of other morphology (the real ICT head and a Live Link Face take), by-name lines."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facepuppet.runtime.files.tables import load_tables
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.kpls.stage import KplsRetarget

from conftest import need_shared
from facepuppet.offline.kpls.commands import fit_kpls, register, to_runtime
from facepuppet.offline.kpls.pairs import match_matrix, pair_weights
from facepuppet.offline.kpls.targets import stylise
from helpers.kpls_characters import bump_character


def _parser():
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    return parser


def test_fit_retarget_with_its_defaults_writes_finite_metrics_and_prints_the_by_name_agreement(tmp_path):
    a = bump_character()
    b = stylise(a, name="bumps (stylised)")  # same topology and names, another face shape
    a.save(tmp_path / "a.npz")
    b.save(tmp_path / "b.npz")
    args = _parser().parse_args(["fit-retarget", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"),
                                 "-o", str(tmp_path / "r.npz")])
    logs = []
    assert args.func(args, log=logs.append) == 0
    meta = load_tables(tmp_path / "r.npz").metadata
    assert meta["metrics"]["cv_mse"] and all(np.isfinite(v) for v in meta["metrics"]["cv_mse"].values())
    text = "\n".join(logs)
    assert "by-name agreement: the retarget equals the by-name mapping within" in text
    assert "a plain by-name map (no --retarget) gives the same result" in text
    for name in a.shape_names:  # one agreement line per target channel
        assert any(line.split()[:1] == [name] for line in logs[2:]), name
    stage = KplsRetarget.load(tmp_path / "r.npz")
    W = pair_weights(8, np.arange(8), 200, seed=7)
    got = np.stack([stage.apply(Frame(t=0.0, channels=a.shape_names, weights=w.astype(np.float32))) for w in W])
    assert np.abs(got - W).max() < 0.02


def test_default_fit_on_the_identical_character_is_the_identity():
    c = bump_character(seed=2)
    model, pairs = fit_kpls(c, c, progress=False)
    assert all(np.isfinite(v) for v in model.cv_errors_.values())
    stage = to_runtime(model, pairs, c, c)
    W = pair_weights(8, np.arange(8), 200, seed=3)
    got = np.stack([stage.predict_weights(w) for w in W])
    assert np.abs(got - W).max() < 0.02


def _take_channels(stage, frames, source, target):
    """Source channels mapped by name onto the target, and the retarget's, over a take."""
    M = match_matrix(source.shape_names, target.shape_names)
    from facepuppet.offline.kpls.cyclic_eval import motion_weights

    W = motion_weights(frames, source)
    got = np.stack([stage.apply(f) for f in frames if f.weights is not None]).astype(np.float64)
    return W @ M.T, got


@pytest.mark.data
@pytest.mark.slow
def test_ict_head_onto_a_variant_keeps_range_and_timing_and_onto_itself_is_the_identity():
    from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv

    from facepuppet.offline.io.rig_import import import_rig

    ict_dir = need_shared("ict-facekit")
    frames = read_llf_csv(need_shared("tracker", "livelinkface_myslate_3.csv"))
    ict = import_rig(ict_dir / "generic_neutral_mesh.obj", ict_dir)
    variant = stylise(ict, eye_scale=1.5, jaw_stretch=0.5, taper=-0.15, name="ICT long jaw")
    for target in (variant, ict):
        model, pairs = fit_kpls(ict, target, progress=False)
        stage = to_runtime(model, pairs, ict, target)
        source, got = _take_channels(stage, frames, ict, target)
        if target is ict:
            assert np.abs(got - source).max() < 0.02
            continue
        moving = np.flatnonzero(source.max(axis=0) >= 0.05)
        assert len(moving) > 30
        for j in moving:
            name = target.shape_names[j]
            assert abs(got[:, j].max() / source[:, j].max() - 1) <= 0.15, name
            assert np.corrcoef(got[:, j], source[:, j])[0, 1] >= 0.95, name
