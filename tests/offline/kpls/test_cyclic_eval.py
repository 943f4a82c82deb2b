"""Training pairs, the cyclic error (eq. 11), fit-retarget and the runtime stage against the offline model."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.kpls.stage import KplsRetarget

from facepuppet.offline.kpls.baselines import LinearRetarget
from facepuppet.offline.kpls.commands import register, to_runtime
from facepuppet.offline.kpls.cyclic_eval import DUTREVE, bar_plot, cyclic_error, evaluate, format_table, improvements
from facepuppet.offline.kpls.model import KernelPLS
from facepuppet.offline.kpls.pairs import (
    covering_points,
    expression_pairs,
    farthest_points,
    feature_matrix,
    feature_points,
    match_matrix,
    pair_weights,
    read_pairing,
    shape_peaks,
)
from facepuppet.offline.kpls.targets import ExaggeratedRigTarget, LinearRigTarget, stylise
from helpers.kpls_characters import SHAPES, bump_character

SIDED = tuple(n.replace("Left", "_L").replace("Right", "_R") for n in SHAPES)


def test_a_character_nothing_moves_has_no_feature_points():
    c = bump_character()
    still = type(c)(**{**c.__dict__, "delta_positions": np.zeros_like(c.delta_positions)})
    with pytest.raises(ValueError, match=r"character 'bumps': its shapes move no vertex; nothing to retarget"):
        feature_points(still, 20)


def test_feature_matrix_matches_dense_deltas_and_points_spread():
    c = bump_character()
    pts = feature_points(c, 20)
    assert len(set(pts.tolist())) == 20
    F = feature_matrix(c, pts)
    dense = c.dense_deltas()[:, pts].reshape(c.n_shapes, -1).T
    np.testing.assert_allclose(F, dense, atol=1e-7)
    # farthest-point sampling: the second point is the farthest from the first
    p = np.random.default_rng(0).normal(size=(50, 3))
    i = farthest_points(p, 2)
    assert i[1] == np.argmax(np.linalg.norm(p - p[i[0]], axis=1))


def test_shapes_pair_by_canonical_name_or_by_file(tmp_path):
    M = match_matrix(SHAPES, SIDED)
    assert M[SIDED.index("eyeBlink_L"), SHAPES.index("eyeBlinkLeft")] == 1 and M.sum() == len(SHAPES)
    f = tmp_path / "pairs.txt"
    f.write_text("# source,target\njawOpen, mouthPucker\n\nEyeBlinkLeft,eyeBlink_R\n")
    M = match_matrix(SHAPES, SIDED, read_pairing(f))
    assert M[SIDED.index("mouthPucker"), 0] == 1 and M[SIDED.index("eyeBlink_R"), SHAPES.index("eyeBlinkLeft")] == 1
    f.write_text("jawOpen\n")
    with pytest.raises(ValueError, match="pairs.txt:1: expected 'source_name,target_name'"):
        read_pairing(f)
    with pytest.raises(ValueError, match="source shape 'nope' is not among"):
        match_matrix(SHAPES, SIDED, [("nope", "jawOpen")])


def test_feature_points_see_every_shape_and_pairs_cover_each_range():
    # a shape whose patch is small and tucked between others: farthest points alone miss it
    c = bump_character()
    for idx, length in shape_peaks(c):
        pts = feature_points(c, 6)
        seen = length[np.isin(idx, pts)]
        assert len(seen) and seen.max() >= 0.5 * length.max()
    assert set(covering_points(c).tolist()) <= set(feature_points(c, 6).tolist())
    W = pair_weights(8, np.arange(8), n_mixes=50)
    for s in range(8):
        alone = W[(W > 0).sum(1) == 1]
        assert sorted(alone[alone[:, s] > 0, s]) == [0.25, 0.5, 0.75, 1.0]
    assert (W > 0).sum(1).max() > 6  # mixes as busy as a real frame, not only pairs and triples


def test_pairs_have_their_own_feature_counts():
    a, b = bump_character(), bump_character(scale=(1.3, 0.8, 1.0), names=SIDED, seed=1)
    pairs = expression_pairs(a, b, n_mixes=40, k_source=15, k_target=11)
    assert pairs.X.shape == (1 + 4 * 8 + 40, 45) and pairs.Y.shape == (73, 8)  # each shape at 4 weights
    assert len(pairs.target_points) == 11
    np.testing.assert_allclose(pairs.X, pairs.source_weights @ pairs.source_features.T)
    np.testing.assert_array_equal(pairs.X[0], 0)


def test_identical_characters_cycle_to_zero_error():
    c = bump_character()
    motion = np.random.default_rng(2).uniform(0, 1, size=(40, 8)) * (np.random.default_rng(3).random((40, 8)) < 0.5)
    methods = {"KPLS linear": lambda: KernelPLS(n_components=8, kernel="linear"), "linear": LinearRetarget}
    rows = evaluate(c, {"same": LinearRigTarget(c, c, k=15)}, motion, methods=methods, n_mixes=60, k_source=15)
    scale = cyclic_error(c, motion, np.zeros_like(motion))
    for r in rows:
        if r["method"] == DUTREVE:  # same face, same points: the warp is the identity, the transfer exact
            assert r["e_target"] < 1e-6, r
        else:
            assert r["e_d"] < 1e-6 * scale and r["e_target"] < 1e-6, r
    # the cycle error itself: zero for the same weights, the mean vertex distance otherwise
    assert cyclic_error(c, motion, motion) == 0.0
    one = np.zeros((1, 8))
    one[0, 0] = 1.0
    moved = np.linalg.norm(c.dense_deltas()[0], axis=1)
    region = np.flatnonzero(np.linalg.norm(c.dense_deltas(), axis=2).max(0) > 0)
    assert cyclic_error(c, one, np.zeros((1, 8))) == pytest.approx(moved[region].mean(), rel=1e-5)


@pytest.mark.slow
def test_other_morphology_cycle_table_and_plot(tmp_path):
    a, b = bump_character(), bump_character(scale=(1.3, 0.8, 1.0), amplitude=1.5, names=SIDED, seed=1)
    motion = np.random.default_rng(4).uniform(0, 0.8, size=(30, 8))
    methods = {"KPLS rbf": lambda: KernelPLS(kernel="rbf"), "linear": LinearRetarget}
    targets = {"other": LinearRigTarget(a, b, k=12), "exaggerated": ExaggeratedRigTarget(a, b, k=12)}
    rows = evaluate(a, targets, motion, methods=methods, n_mixes=80, k_source=15)
    scale = cyclic_error(a, motion, np.zeros_like(motion))
    assert all(0 <= r["e_d"] < (scale if r["method"] == DUTREVE else 0.2 * scale) for r in rows)
    assert {r["method"] for r in rows} == {"KPLS rbf", "linear", DUTREVE}
    imp = improvements(rows)["other"]["linear"]
    errs = {r["method"]: r["e_d"] for r in rows if r["target"] == "other"}
    if errs["linear"] > 1e-9 * max(errs.values()):
        assert imp == pytest.approx(100 * (errs["linear"] - errs["KPLS rbf"]) / errs["linear"])
    else:  # the linear map is exact on a linear correspondence: no ratio to print
        assert imp is None
    assert "KPLS rbf" in format_table(rows, "cm")
    png = bar_plot(rows, tmp_path / "bars.png", "cm")
    from PIL import Image

    assert Image.open(png).size == (960, 480)


class _ArcTarget:
    """One target feature point swinging on an arc: angle from jawOpen (to 270°), radius from the left smile.

    Neither weight is a linear function of the target's point, so no linear map inverts the
    correspondence, while the map is smooth and one-to-one.
    """

    linear = False
    matched = np.array([0, 1])
    points = np.array([0])

    def __init__(self, character):
        self.character, self.n_source = character, character.n_shapes
        self.neutral_points = character.vertices[:1].astype(np.float64)

    def features(self, W):
        angle, radius = 1.5 * np.pi * W[:, 0], 1.0 + W[:, 1]
        return np.stack([radius * np.sin(angle), radius * (1 - np.cos(angle)), 0 * angle], 1)


def test_kpls_rbf_beats_linear_regression_on_a_nonlinear_correspondence():
    a = bump_character()
    motion = np.zeros((50, 8))
    motion[:, :2] = np.random.default_rng(4).uniform(0.1, 0.9, size=(50, 2))
    methods = {"KPLS rbf": lambda: KernelPLS(kernel="rbf"), "linear": LinearRetarget}
    rows = evaluate(a, {"arc": _ArcTarget(a)}, motion, methods=methods, n_mixes=120, k_source=15, dutreve=False)
    err = {r["method"]: r for r in rows}
    assert err["KPLS rbf"]["e_d"] < 0.5 * err["linear"]["e_d"], rows
    assert err["KPLS rbf"]["e_target"] < 0.1 * err["linear"]["e_target"], rows


def test_linear_methods_cycle_a_monotone_exaggeration_almost_exactly():
    """Why eq. 11 favours linear maps: a backward regression from many non-linear target features
    recovers the source weights linearly, so the cycle closes although the forward map is wrong."""
    a, b = bump_character(), bump_character(scale=(1.3, 0.8, 1.0), names=SIDED, seed=1)
    motion = np.random.default_rng(6).uniform(0, 0.8, size=(30, 8))
    rows = evaluate(a, {"x": ExaggeratedRigTarget(a, b, k=12)}, motion, methods={"linear": LinearRetarget},
                    n_mixes=80, k_source=15, dutreve=False)
    scale = cyclic_error(a, motion, np.zeros_like(motion))
    assert rows[0]["e_d"] < 0.01 * scale
    true = ExaggeratedRigTarget(a, b, k=12).features(motion).reshape(30, -1, 3)
    assert rows[0]["e_target"] > 0.02 * np.linalg.norm(true, axis=2).mean()


def test_stylise_warps_neutral_and_shapes_consistently():
    c = bump_character()
    s = stylise(c, eye_scale=1.0, jaw_stretch=0.0, taper=0.0)  # identity warp
    np.testing.assert_allclose(s.vertices, c.vertices, atol=1e-6)
    np.testing.assert_allclose(s.dense_deltas(), c.dense_deltas(), atol=1e-6)
    s = stylise(c)
    assert not np.allclose(s.vertices, c.vertices) and s.shape_names == c.shape_names


def test_fit_retarget_command_and_runtime_stage_agree_with_the_offline_model(tmp_path):
    a, b = bump_character(), bump_character(scale=(1.3, 0.8, 1.0), names=SIDED, seed=1)
    a.save(tmp_path / "a.npz")
    b.save(tmp_path / "b.npz")
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["fit-retarget", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "-o",
                              str(tmp_path / "r.npz"), "--kernel", "poly", "--components", "6",
                              "--source-points", "15", "--target-points", "12", "--mixes", "60"])
    logs = []
    assert args.func(args, log=logs.append) == 0 and "6 components" in logs[0]
    stage = KplsRetarget.load(tmp_path / "r.npz")
    assert stage.target_names == b.shape_names and stage.kernel == "poly"
    # the same model offline
    pairs = expression_pairs(a, b, n_mixes=60, k_source=15, k_target=12)
    model = KernelPLS(n_components=6, kernel="poly").fit(pairs.X, pairs.Y)
    W = np.random.default_rng(5).uniform(0, 1, size=(20, 8))
    offline = model.predict(W @ pairs.source_features.T)
    online = np.stack([stage.apply(Frame(t=0.0, channels=a.shape_names, weights=w)) for w in W])
    np.testing.assert_allclose(online, offline, rtol=0, atol=1e-3)  # float32 tables: 0.1 % of a full weight
    # and the in-memory stage (before the tables file) predicts the same
    mem = to_runtime(model, pairs, a, b)
    np.testing.assert_allclose(np.stack([mem.predict_weights(w) for w in W]), offline, rtol=0,
                               atol=1e-3)
    with pytest.raises(SystemExit):
        parser.parse_args(["fit-retarget", "a", "b", "-o", "r", "--components", "0"])


def test_table_prints_n_a_where_a_method_has_zero_error():
    rows = [{"target": "same", "method": "KPLS rbf", "e_d": 5.2e-5, "e_target": 1e-4},
            {"target": "same", "method": "linear regression", "e_d": 1e-19, "e_target": 2e-4},
            {"target": "same", "method": "RBF on pairs", "e_d": 1e-4, "e_target": 0.0}]
    assert improvements(rows)["same"]["linear regression"] is None
    assert improvements(rows)["same"]["RBF on pairs"] == pytest.approx(48.0)
    table = format_table(rows)
    assert "0.0000 (n/a)" in table.splitlines()[3] and "(+48%)" in table.splitlines()[4]
    assert "0.0000 (n/a)" in format_table(rows, key="e_target").splitlines()[4]


def test_one_method_blowing_up_does_not_turn_its_column_into_n_a():
    rows = [{"target": "demo", "method": "KPLS rbf", "e_d": 0.0361, "e_target": 0.0046},
            {"target": "demo", "method": "linear PLS", "e_d": 0.0550, "e_target": 0.0333},
            {"target": "demo", "method": "Dutreve spatial RBF", "e_d": 8.2e13, "e_target": 0.43}]
    imp = improvements(rows)["demo"]
    assert imp["linear PLS"] == pytest.approx(100 * (0.0550 - 0.0361) / 0.0550)
    assert imp["Dutreve spatial RBF"] == pytest.approx(100.0)
    assert "(+34%)" in format_table(rows).splitlines()[3]



def test_feature_points_never_sit_on_one_place_twice():
    """The demo head has seam vertices (two indices, one position): two feature points there made the
    Dutreve RBF over them singular (its cyclic error 8e13 cm in bench kpls)."""
    from scipy.spatial.distance import pdist

    from facepuppet.runtime.demo.head import build_demo_character

    from facepuppet.offline.kpls.pairs import feature_points

    demo = build_demo_character()
    points = feature_points(demo, 45)
    size = float(np.linalg.norm(np.ptp(demo.vertices, axis=0)))
    assert pdist(demo.vertices[points].astype(np.float64)).min() > 1e-6 * size
