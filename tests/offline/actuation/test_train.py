"""Shin & Lee training: ground-truth recovery, cubic fit, mean-shift, bad inputs, the commands."""

from __future__ import annotations

import argparse
import warnings

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.model.rigid import kabsch

from facepuppet.offline.actuation import commands as actor_commands
from facepuppet.offline.actuation.basis import ActuationModel, class_axes, mean_shift
from facepuppet.offline.actuation.cubic_fit import evaluate, fit_polynomial
from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
from facepuppet.offline.actuation.train import train_actor
from facepuppet.offline.io.capture import Capture, write_trc

K = 6
TRAIN = 1300


@pytest.fixture(scope="module")
def trained():
    cap, truth = synthetic_capture(n_frames=1500, n_markers=40, k=K, seed=1)
    train = Capture(cap.markers[:TRAIN], cap.names, cap.rate, cap.units, "synthetic")   # the rest is held out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        model = train_actor(train, k=K, head_markers=["M00", "M01", "M02", "M03"])
    return cap, truth, model


def test_recovers_known_actuations_up_to_permutation_sign_and_scale(trained):
    cap, truth, model = trained
    s_true = truth["s"][model.training_frames_]
    corr = np.corrcoef(s_true.T, model.s_.T)[:K, K:]
    rows, cols = linear_sum_assignment(-np.abs(corr))
    matched = np.abs(corr[rows, cols])
    assert matched.min() > 0.85, matched
    # s = 0 is the neutral and s = 1 a strong actuation
    neutral = model.actor_.metadata["settings"]["neutral_frame"]
    np.testing.assert_allclose(model.actuation_.transform(model.stabilised_.markers[neutral:neutral + 1]
                                                          - model.actor_.neutral), 0.0, atol=1e-9)
    assert np.all(np.quantile(model.s_, 0.99, axis=0) == pytest.approx(1.0, abs=1e-6))


def test_solve_reproduces_held_out_frames(trained):
    cap, truth, model = trained
    actor = model.actor_
    solver = MarkerSolver(actor, iterations=20)
    head = actor.head_markers
    errors, spread = [], []
    for f in range(TRAIN, 1500, 5):                 # frames the training never saw
        seen = cap.markers[f].astype(np.float64)
        if np.isnan(seen).any():
            continue
        r, t = kabsch(actor.neutral[head], seen[head])    # into the actor's head coordinates
        seen = seen @ r.T + t
        solver.solve(seen)
        errors.append(np.sqrt(np.mean(np.sum((actor.evaluate(solver.s) - seen) ** 2, axis=1))))
        spread.append(np.sqrt(np.mean(np.sum((seen - actor.neutral) ** 2, axis=1))))
    errors, spread = np.array(errors), np.array(spread)
    moving = spread > np.median(spread)             # frames with a real expression
    assert np.median(errors[moving]) < 0.2 * np.median(spread[moving]), (np.median(errors), np.median(spread))


def test_cubic_fit_recovers_exact_coefficients_and_matches_lstsq():
    rng = np.random.default_rng(0)
    s = rng.uniform(-0.2, 1.2, (200, 3))
    coef = rng.normal(size=(3, 3, 5))
    y = evaluate(coef, s)
    np.testing.assert_allclose(fit_polynomial(s, y, 3, ridge=0.0), coef, atol=1e-8)
    y[5, 2] = np.nan                               # a gap: that column fitted from its own rows
    phi = np.c_[s ** 3, s ** 2, s]
    ref = np.stack([np.linalg.lstsq(phi[~np.isnan(y[:, j])], y[~np.isnan(y[:, j]), j], rcond=None)[0]
                    for j in range(5)], axis=1)
    np.testing.assert_allclose(fit_polynomial(s, y, 3, ridge=0.0).reshape(9, 5), ref, atol=1e-8)


def test_numpy_mean_shift_matches_scikit_learn():
    from sklearn.cluster import MeanShift

    rng = np.random.default_rng(2)
    dirs = np.vstack([rng.normal([0, 1, 0], 0.1, (40, 3)), rng.normal([0, -1, 0.3], 0.1, (25, 3))])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    centres, labels = mean_shift(dirs, 0.5)
    ref = MeanShift(bandwidth=0.5).fit(dirs)
    assert len(centres) == len(ref.cluster_centers_) == 2
    order = [int(np.argmin(np.linalg.norm(ref.cluster_centers_ - c, axis=1))) for c in centres]
    np.testing.assert_allclose(centres, ref.cluster_centers_[order], atol=1e-6)
    np.testing.assert_array_equal(np.asarray(order)[labels], ref.labels_)


def test_class_axes_sklearn_and_numpy_agree(trained):
    """The vectorised mean-shift finds the same classes as scikit-learn's on almost every marker."""
    cap, truth, model = trained
    # every other marker (2 head, 18 moving) of 600 frames: the same take, half the mean-shift calls
    disp = (model.stabilised_.markers[:600] - model.actor_.neutral)[:, ::2]
    a1, m1 = class_axes(disp)
    a2, m2 = class_axes(disp, method="sklearn")
    markers = np.union1d(m1, m2)
    same = [i for i in markers if (m1 == i).sum() == (m2 == i).sum()]
    assert len(markers) >= 12 and len(a1) >= len(markers) + 5          # several markers with several classes
    assert len(same) >= 0.8 * len(markers), (len(same), len(markers))
    for i in same:
        d = np.abs(a1[m1 == i] @ a2[m2 == i].T)
        assert d.max(axis=1).min() > 0.99


def test_k_larger_than_possible_and_bad_k(trained):
    cap, truth, model = trained
    disp = model.stabilised_.markers[:200] - model.actor_.neutral
    with pytest.raises(ValueError, match=r"K = 5000 is larger than possible: the take yields \d+ actuation signals"):
        ActuationModel(5000).fit(disp)
    with pytest.raises(ValueError, match="n_components"):
        ActuationModel(0).fit(disp)


def test_train_actor_command_writes_tables_and_pictures(tmp_path, capsys):
    cap, _ = synthetic_capture(n_frames=600, n_markers=20, k=3, seed=4)
    trc = write_trc(tmp_path / "take.trc", cap)
    parser = argparse.ArgumentParser()
    actor_commands.register(parser.add_subparsers())
    args = parser.parse_args(["train-actor", str(trc), "-o", str(tmp_path / "actor.npz"), "--k", "3",
                              "--head-markers", "M00", "M01", "M02", "M03", "--pictures", str(tmp_path / "pics")])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "held-out RMS marker error: linear" in out and "K report" in out
    actor = Actor.load(tmp_path / "actor.npz")
    assert actor.n_actuations == 3 and actor.names == cap.names and actor.units == "cm"
    from PIL import Image

    sheet = np.asarray(Image.open(tmp_path / "pics" / "actuations.png"))
    assert sheet.shape[2] == 3 and sheet.std() > 5           # figures were drawn, not a blank image
    assert Image.open(tmp_path / "pics" / "signals.png").size[0] == 1200


def test_ridge_on_cubic_terms_shrinks_towards_linear_and_is_chosen_by_held_out_error():
    from facepuppet.offline.actuation.cubic_fit import choose_ridge_ab, holdout_errors

    rng = np.random.default_rng(3)
    s = rng.uniform(0.0, 1.0, (300, 3))
    c = rng.normal(size=(3, 4 * 3))
    linear_truth = s @ c
    np.testing.assert_allclose(fit_polynomial(s, linear_truth, 3, ridge_ab=1e6)[2],
                               fit_polynomial(s, linear_truth, 1)[0], atol=1e-3)
    assert np.abs(fit_polynomial(s, linear_truth, 3, ridge_ab=1e6)[:2]).max() < 1e-3
    # a linear truth under heavy noise: the curvature is noise, so a ridge wins on held-out frames
    noisy = linear_truth + rng.normal(scale=1.0, size=linear_truth.shape)
    chosen, table = choose_ridge_ab(s, noisy, 4)
    assert chosen > 0 and len(table) == 7
    # a strongly cubic truth with little noise: no (or a tiny) ridge, and the cubic beats the linear model
    coef = rng.normal(size=(3, 3, 12)) * 2.0
    cubic_truth = evaluate(coef, s) + rng.normal(scale=0.01, size=linear_truth.shape)
    chosen, _ = choose_ridge_ab(s, cubic_truth, 4)
    assert chosen <= 1e-2
    h = holdout_errors(s, cubic_truth, 4)
    assert h["cubic_ridge_rms"] < 0.2 * h["linear_rms"] and h["cubic_ridge_rms"] <= 1.05 * h["cubic_rms"]
