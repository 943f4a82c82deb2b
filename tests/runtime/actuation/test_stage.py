"""The Retarget stage: marker frames -> solver -> ActorPair (§6.2) -> target weights."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.actuation.stage import ActorRetarget
from facepuppet.runtime.frames import Frame

from helpers.small_actors import K, N, make_actor


def test_retarget_stage_turns_marker_frames_into_weights(tmp_path):
    actor = make_actor()
    cubic = np.zeros((3, K, 2))
    cubic[2, 0, 0] = 1.0                                  # w0 = s0, w1 = s1^2
    cubic[1, 1, 1] = 1.0
    pair = ActorPair(cubic=cubic, shape_names=("a", "b"), marker_names=actor.names,
                     marker_vertices=np.arange(N), similarity=np.eye(4), s_lower=actor.s_lower,
                     s_upper=actor.s_upper)
    pair = ActorPair.load(pair.save(tmp_path / "pair.npz"))
    stage = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30))
    s_true = np.array([0.7, 0.5, 0.0, 0.0])
    # a rigidly moved head, names in another order, one marker missing
    angle = 0.2
    rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    markers = actor.evaluate(s_true) @ rot.T + [3.0, -1.0, 2.0]
    order = np.arange(N)[::-1]
    markers = markers[order]
    markers[0] = np.nan
    frame = Frame(t=0.0, source="markers", markers=markers, marker_names=tuple(actor.names[i] for i in order))
    weights = stage.apply(frame)
    assert stage.target_names == ("a", "b")
    np.testing.assert_allclose(weights, [0.7, 0.25], atol=0.03)
    assert stage.apply(Frame(t=0.1, source="x")) is None


def _stage():
    actor = make_actor()
    cubic = np.zeros((3, K, 2))
    cubic[2, 0, 0] = 1.0
    cubic[1, 1, 1] = 1.0
    pair = ActorPair(cubic=cubic, shape_names=("a", "b"), marker_names=actor.names,
                     marker_vertices=np.arange(N), similarity=np.eye(4), s_lower=actor.s_lower,
                     s_upper=actor.s_upper)
    return actor, ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30))


def test_absurd_marker_values_are_counted_not_warned_about_per_frame():
    """Finite but absurd coordinates (3e38, a fuzzed packet) pass the loop's finiteness check; the stage
    must not overflow into NumPy RuntimeWarnings every frame, and must not hand on non-finite weights."""
    import warnings

    actor, stage = _stage()
    good = actor.evaluate(np.array([0.7, 0.5, 0.0, 0.0]))
    outputs = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        for i, value in enumerate([3e38, -3e38, 1e30, 1e20]):  # float32, as markers arrive
            markers = good.copy()
            markers[i % N, 1] = value            # a head marker among them (markers 0..2)
            outputs.append(stage.apply(Frame(t=i / 60, source="markers", markers=markers,
                                             marker_names=actor.names)))
        head = good.copy()
        head[:3] = 3e38                          # every head marker absurd: no head pose
        outputs.append(stage.apply(Frame(t=1.0, source="markers", markers=head, marker_names=actor.names)))
    # the actor has exactly 3 head markers (0..2): an absurd one leaves too few for the head pose
    assert [w is None for w in outputs] == [True, True, True, False, True]
    assert np.isfinite(outputs[3]).all()
    assert stage.counters["no_head_pose"] == 4 and stage.counters["out_of_range"] == 5
    assert np.isfinite(stage.head_rotation).all() and np.isfinite(stage.s).all()
