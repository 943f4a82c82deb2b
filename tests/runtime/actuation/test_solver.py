"""The bounded LM marker solver (eq 5): recovery, bounds, early stops, direct manipulation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from facepuppet.runtime.actuation.solver import MarkerSolver

from helpers.small_actors import K, N, make_actor


def test_solver_recovers_s_and_matches_a_reference_least_squares():
    actor = make_actor()
    s_true = np.array([0.8, 0.1, 0.5, 0.3])
    obs = actor.evaluate(s_true)
    solver = MarkerSolver(actor, iterations=50, damping=0.0, prior=0.0, tolerance=1e-10, cost_tolerance=0.0)
    np.testing.assert_allclose(solver.solve(obs), s_true, atol=1e-5)
    # with occlusions and the default (damped) settings: same answer as scipy's bounded TRF on eq 5
    obs[[4, 7]] = np.nan
    fast = MarkerSolver(actor, iterations=50).solve(obs, s0=np.zeros(K))
    keep = ~np.isnan(obs).any(axis=1)
    ref_solver = MarkerSolver(actor)
    lam, mu = ref_solver.damping, ref_solver.prior

    def residual(s):
        return np.r_[(actor.evaluate(s)[keep] - obs[keep]).ravel(), np.sqrt(lam) * s, np.sqrt(mu) * s]

    ref = least_squares(residual, np.zeros(K), bounds=(actor.s_lower, actor.s_upper), xtol=1e-12).x
    np.testing.assert_allclose(fast, ref, atol=1e-4)


def test_solver_respects_bounds_budget_and_missing_markers():
    actor = make_actor()
    solver = MarkerSolver(actor, iterations=3)
    far = actor.evaluate(np.full(K, 5.0))           # outside the bounds
    s = solver.solve(far)
    assert np.all(s <= actor.s_upper + 1e-6) and solver.last_iterations <= 3
    before = solver.s.copy()
    np.testing.assert_array_equal(solver.solve(np.full((N, 3), np.nan)), before)   # nothing seen: keep s
    with pytest.raises(ValueError, match=r"observed must be \(12, 3\)"):
        solver.solve(np.zeros((N + 1, 3)))


def test_early_stops_only_at_the_converged_solution():
    """The step and cost-gain stops end the solve early only where a long, tight solve ends too.

    Frames far from the warm start (and from the damping anchor), with noise and occlusions: the
    solver must stop by its criteria (well inside the budget) at the solution that a 500-step solve
    with no early stop reaches from the same start.
    """
    actor = make_actor()
    rng = np.random.default_rng(1)
    for trial in range(12):
        s_true = rng.uniform(0.0, 1.2, K)
        start = rng.uniform(-0.5, 1.5, K) if trial % 3 else np.zeros(K)
        obs = actor.evaluate(s_true) + rng.normal(scale=0.05, size=(N, 3))
        if trial % 2:
            obs[rng.choice(np.arange(3, N), 5, replace=False)] = np.nan
        fast = MarkerSolver(actor, iterations=30)
        slow = MarkerSolver(actor, iterations=500, tolerance=1e-12, cost_tolerance=0.0)
        fast.s, slow.s = start.copy(), start.copy()
        got, want = fast.solve(obs), slow.solve(obs)
        assert np.abs(start - want).max() > 0.3                     # the solve had far to go
        assert fast.last_iterations < 30                             # stopped by a criterion, not the budget
        assert slow.last_iterations > fast.last_iterations
        np.testing.assert_allclose(got, want, atol=5e-4)


def test_one_dragged_point_moves_the_face_through_s():
    actor = make_actor()
    solver = MarkerSolver(actor)
    rest = actor.evaluate(np.zeros(K))
    movable = np.abs(actor.cubic[2]).sum(axis=(0, 2))
    i = int(np.argmax(movable))                      # the most movable marker
    k = int(np.argmax(np.linalg.norm(actor.cubic[2, :, i], axis=1)))
    target = actor.evaluate(np.eye(K)[k] * 0.8)[i]    # where actuation k would take it
    s = solver.solve_constraints([(i, target)])
    moved = actor.evaluate(s)
    assert np.linalg.norm(moved[i] - target) < 0.2 * np.linalg.norm(target - rest[i])
    # the face follows: other markers move the way the driving actuation moves them
    others = np.setdiff1d(np.flatnonzero(np.linalg.norm(actor.cubic[2, k], axis=1) > 0.1), [i])
    expected = actor.evaluate(np.eye(K)[k] * 0.8)[others] - rest[others]
    got = moved[others] - rest[others]
    cos = np.sum(expected * got, axis=1) / (np.linalg.norm(expected, axis=1) * np.linalg.norm(got, axis=1))
    assert np.median(cos) > 0.7
    np.testing.assert_allclose(moved[:3], rest[:3], atol=1e-9)    # head markers never move


def test_pinned_points_stay_while_another_is_dragged():
    actor = make_actor()
    solver = MarkerSolver(actor)
    start = actor.evaluate(solver.s)
    movable = np.argsort(-np.abs(actor.cubic[2]).sum(axis=(0, 2)))
    drag, pins = int(movable[0]), [int(p) for p in movable[1:3]]
    target = start[drag] + np.array([0.0, -0.6, 0.2])
    free = MarkerSolver(actor).solve_constraints([(drag, target)])
    pinned = solver.solve_constraints([(drag, target)], pins=pins)
    moved_free = np.linalg.norm(actor.evaluate(free)[pins] - start[pins], axis=1)
    moved_pinned = np.linalg.norm(actor.evaluate(pinned)[pins] - start[pins], axis=1)
    assert moved_pinned.max() < 0.3 * max(moved_free.max(), 1e-9) or moved_pinned.max() < 1e-3
    with pytest.raises(ValueError, match="pin index 99 out of range"):
        solver.solve_constraints([(drag, target)], pins=[99])
