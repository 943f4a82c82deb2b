"""Markers adapter (/facepuppet/markers namespace) fed with crafted datagrams."""

from __future__ import annotations

import math

import numpy as np
import pytest

from facepuppet.runtime.inputs.markers import FRAME, LAYOUT, MAX_LAYOUTS, MAX_MARKERS, MarkersAdapter

from helpers.osc_helpers import bundle, counts, msg

NAMES = ("nose", "chin", "mouthL")
POINTS = np.array([[0.0, 10.0, 5.0], [0.0, -40.0, 2.0], [np.nan, np.nan, np.nan]], dtype="<f4")


def layout(layout_id=1, names=NAMES):
    return msg(LAYOUT, layout_id, *names)


def frame(layout_id=1, number=7, t_sender=(12.25, "d"), points=POINTS):
    return msg(FRAME, layout_id, number, t_sender, (np.asarray(points, "<f4").tobytes(), "b"))


def test_layout_then_frame_gives_named_markers_with_nan_for_occluded():
    a = MarkersAdapter()
    assert a.handle(layout().dgram, 0.0) is None
    f = a.handle(frame().dgram, 1.5)
    assert f.marker_names == NAMES and f.number == 7 and f.t_sender == 12.25 and f.t == 1.5
    np.testing.assert_array_equal(f.markers, POINTS)  # NaN compares equal here: occluded stays NaN
    assert f.weights is None and f.source == "markers"
    g = a.handle(frame(number=8, t_sender=3.5).dgram, 1.6)  # float sender time works too
    assert g.t_sender == 3.5 and g.number == 8
    counts(a, datagrams=3, frames=2)


def test_layout_and_frame_in_one_bundle_and_layout_replacement():
    a = MarkersAdapter()
    f = a.handle(bundle(layout(5, ("a",)), frame(5, points=[[1.0, 2.0, 3.0]])), 0.0)
    assert f.marker_names == ("a",)
    f = a.handle(bundle(layout(5, ("a", "b")), frame(5, points=[[1, 2, 3], [4, 5, 6]])), 0.1)
    assert f.marker_names == ("a", "b")
    counts(a, datagrams=2, frames=2)


def test_only_the_newest_layouts_are_kept():
    a = MarkersAdapter()
    for i in range(MAX_LAYOUTS + 1):
        a.handle(layout(i).dgram, 0.0)
    assert 0 not in a.layouts and len(a.layouts) == MAX_LAYOUTS
    assert a.handle(frame(0).dgram, 0.1) is None  # evicted: unknown layout
    counts(a, datagrams=MAX_LAYOUTS + 2, malformed=1)


@pytest.mark.parametrize("message", [
    frame(layout_id=9),                                       # undeclared layout
    frame(points=POINTS[:2]),                                 # blob for 2 markers, layout has 3
    msg(FRAME, 1, 7, 1.0, (b"\x00" * 35, "b")),               # not a multiple of 12
    msg(FRAME, 1, 7, 1.0),                                    # blob missing
    msg(FRAME, 1.0, 7, 1.0, (POINTS.tobytes(), "b")),         # layout id is a float
    msg(FRAME, 1, 7, "now", (POINTS.tobytes(), "b")),
    msg(FRAME, 1, 7, 1.0, "not a blob"),
    msg(LAYOUT, 2),                                           # no names
    msg(LAYOUT, "2", "a"),
    msg(LAYOUT, 2, "a", "a"),                                 # duplicate names
    msg(LAYOUT, 2, "a", 3),
])
def test_malformed_messages_are_counted(message):
    a = MarkersAdapter()
    a.handle(layout().dgram, 0.0)
    assert a.handle(message.dgram, 0.1) is None
    assert a.handle(frame().dgram, 0.2) is not None  # the declared layout still works
    counts(a, datagrams=3, frames=1, malformed=1)


def test_oversized_layouts_and_blobs_are_refused():
    a = MarkersAdapter()
    names = [f"m{i}" for i in range(MAX_MARKERS + 1)]
    assert a.handle(msg(LAYOUT, 3, *names).dgram, 0.0) is None
    big = np.zeros((MAX_MARKERS + 1, 3), "<f4")
    assert a.handle(frame(points=big).dgram, 0.1) is None
    assert a.handle(b"/" + bytes(66000), 0.2) is None
    assert a.handle(msg(LAYOUT, 4, *names[:MAX_MARKERS]).dgram, 0.3) is None  # 1024 is allowed
    assert a.handle(frame(4, points=big[:MAX_MARKERS]).dgram, 0.4).markers.shape == (MAX_MARKERS, 3)
    counts(a, datagrams=5, frames=1, oversized=3)


def test_infinite_coordinates_are_rejected_extra_args_ignored():
    a = MarkersAdapter()
    a.handle(layout().dgram, 0.0)
    bad = POINTS.copy()
    bad[0, 1] = math.inf
    assert a.handle(frame(points=bad).dgram, 0.1) is None
    extra = msg(FRAME, 1, 9, 1.0, (POINTS.tobytes(), "b"), "extra", 4)
    assert a.handle(extra.dgram, 0.2).number == 9
    counts(a, datagrams=3, frames=1, nonfinite=1)


def test_unknown_addresses_empty_and_truncated():
    a = MarkersAdapter()
    a.handle(layout().dgram, 0.0)
    assert a.handle(msg("/facepuppet/markers/other", 1).dgram, 0.1) is None
    assert a.handle(b"", 0.2) is None
    data = frame().dgram
    for n in range(1, len(data)):
        assert a.handle(data[:n], 1.0 + n) is None
    counts(a, datagrams=len(data) + 2, unknown_address=1, malformed=len(data))


def test_declared_units_are_converted_into_the_units_asked_for():
    from facepuppet.runtime.inputs.markers import UNITS

    a = MarkersAdapter(to_units="cm")
    a.handle(bundle(layout(), msg(UNITS, 1, "mm")), 0.0)
    f = a.handle(frame().dgram, 0.1)
    np.testing.assert_allclose(f.markers, POINTS / 10)          # mm -> cm; NaN stays NaN
    a.handle(msg(UNITS, 1, "m").dgram, 0.2)                      # a new declaration replaces the old
    np.testing.assert_allclose(a.handle(frame().dgram, 0.3).markers, POINTS * 100)
    counts(a, datagrams=4, frames=2)


def test_marker_units_option_is_the_default_and_a_declaration_overrides_it():
    from facepuppet.runtime.inputs.markers import UNITS

    a = MarkersAdapter(units="mm", to_units="m")
    a.handle(layout().dgram, 0.0)
    np.testing.assert_allclose(a.handle(frame().dgram, 0.1).markers, POINTS / 1000)
    a.handle(msg(UNITS, 1, "cm").dgram, 0.2)
    np.testing.assert_allclose(a.handle(frame().dgram, 0.3).markers, POINTS / 100)
    b = MarkersAdapter()                                         # nobody asked for units: as sent
    b.handle(bundle(layout(), msg(UNITS, 1, "mm")), 0.0)
    np.testing.assert_array_equal(b.handle(frame().dgram, 0.1).markers, POINTS)


@pytest.mark.parametrize("message", [msg("/facepuppet/markers/units", 1, "inch"),
                                     msg("/facepuppet/markers/units", 2, "mm"),   # undeclared layout
                                     msg("/facepuppet/markers/units", 1)])
def test_bad_units_messages_are_counted_as_malformed(message):
    a = MarkersAdapter(to_units="cm")
    a.handle(layout().dgram, 0.0)
    assert a.handle(message.dgram, 0.1) is None
    np.testing.assert_array_equal(a.handle(frame().dgram, 0.2).markers, POINTS)
    counts(a, datagrams=3, frames=1, malformed=1)


def test_unknown_units_are_refused_when_the_adapter_is_made():
    with pytest.raises(ValueError, match="units must be one of mm, cm, m, got 'inch'"):
        MarkersAdapter(units="inch")
