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


def _pair(actor):
    cubic = np.zeros((3, K, 2))
    cubic[2, 0, 0] = 1.0
    cubic[1, 1, 1] = 1.0
    pair = ActorPair(cubic=cubic, shape_names=("a", "b"), marker_names=actor.names,
                     marker_vertices=np.arange(N), similarity=np.eye(4), s_lower=actor.s_lower,
                     s_upper=actor.s_upper)
    return pair


def _stage():
    actor = make_actor()
    return actor, ActorRetarget(actor, _pair(actor), MarkerSolver(actor, iterations=30))


def _pair_for(actor, tmp_path):
    return ActorPair.load(_pair(actor).save(tmp_path / "pair.npz"))


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


def _datagrams(names, points_mm, units=None):
    from facepuppet.runtime.inputs.markers import FRAME, LAYOUT, UNITS

    from helpers.osc_helpers import bundle, msg

    parts = [msg(LAYOUT, 1, *names)] + ([msg(UNITS, 1, units)] if units else [])
    return bundle(*parts), msg(FRAME, 1, 0, 0.0, (np.asarray(points_mm, "<f4").tobytes(), "b")).dgram


def test_frames_in_mm_to_an_actor_in_cm_are_converted_when_declared_and_warned_about_when_not(tmp_path):
    from facepuppet.runtime.inputs.markers import MarkersAdapter

    actor = make_actor()                                  # units cm
    pair = _pair_for(actor, tmp_path)
    s_true = np.array([0.7, 0.5, 0.0, 0.0])
    in_mm = actor.evaluate(s_true) * 10.0
    expected = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30)).apply(
        Frame(t=0.0, markers=actor.evaluate(s_true), marker_names=actor.names))
    for units, option in (("mm", None), (None, "mm")):   # the layout says mm, or --marker-units mm
        lines = []
        stage = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30), log=lines.append)
        adapter = MarkersAdapter(units=option, to_units=actor.units)
        layout, frame = _datagrams(actor.names, in_mm, units)
        adapter.handle(layout, 0.0)
        weights = stage.apply(adapter.handle(frame, 0.1))
        np.testing.assert_allclose(weights, expected, atol=1e-4)
        assert lines == []
    lines = []                                            # undeclared: taken as cm, 10x too big, warned once
    stage = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30), log=lines.append)
    for t in range(3):
        stage.apply(Frame(t=t, markers=in_mm, marker_names=actor.names))
    import re

    assert len(lines) == 1
    ratio = re.search(r"spread ([0-9.]+)x the actor's neutral \(cm\)", lines[0])
    assert ratio and 9 < float(ratio.group(1)) < 11      # the expression moves a few markers: about 10x
    assert "--marker-units" in lines[0]


def test_unmatched_and_missing_marker_names_are_reported_once(tmp_path):
    actor = make_actor()
    pair = _pair_for(actor, tmp_path)
    lines = []
    stage = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30), log=lines.append)
    names = list(actor.names)
    names[5], names[7] = "LeftBrow", "chin_tip"          # two names the actor does not know
    markers = actor.evaluate(np.zeros(K))
    for t in range(3):
        assert stage.apply(Frame(t=t, markers=markers, marker_names=tuple(names))) is not None
    assert len(lines) == 1
    assert "matches 10 of the actor's 12" in lines[0]
    assert "not the actor's (ignored): LeftBrow, chin_tip" in lines[0]
    assert "the actor's, not in the layout: m5, m7" in lines[0]


def test_a_layout_sharing_too_few_markers_is_refused_and_counted(tmp_path):
    actor = make_actor()                                  # head markers m0..m2, K = 4: needs 3 + 2
    pair = _pair_for(actor, tmp_path)
    lines = []
    stage = ActorRetarget(actor, pair, MarkerSolver(actor, iterations=30), log=lines.append)
    assert stage.needs() == (3, 2)
    markers = actor.evaluate(np.zeros(K))
    names = ("m0", "m1", "m2", "m3") + tuple(f"x{i}" for i in range(N - 4))   # 3 head + 1 other
    for t in range(2):
        assert stage.apply(Frame(t=t, markers=markers, marker_names=names)) is None
    assert stage.counters["layout_refused"] == 2
    assert len(lines) == 1 and "refused" in lines[0] and "needs 3 head markers and 2 others" in lines[0]
    names = ("x0", "m1", "m2") + actor.names[3:]          # a head marker missing: refused too
    assert stage.apply(Frame(t=3, markers=markers, marker_names=names)) is None
    assert "shares 2 of the actor's 3 head markers" in lines[-1]
    assert stage.apply(Frame(t=4, markers=markers, marker_names=actor.names)) is not None
