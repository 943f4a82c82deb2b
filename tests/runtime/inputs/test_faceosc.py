"""FaceOSC adapter fed with crafted bundles: gestures to channels, running neutral, found, raw, counters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder

from facepuppet.runtime.inputs.faceosc import RESET_SPANS, SPANS, TAU_ACTIVE, FaceOscAdapter
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

from helpers.osc_helpers import counts, msg

INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}
REST = {"mouth/height": 1.0, "mouth/width": 14.0, "eyebrow/left": 7.5, "eyebrow/right": 7.5,
        "eye/left": 2.8, "eye/right": 2.8, "jaw": 20.0, "nostrils": 6.0}


def frame_bundle(found=1, **gestures):
    """One FaceOSC frame: /found then every gesture (rest values unless overridden)."""
    values = dict(REST)
    values.update({k.replace("__", "/"): v for k, v in gestures.items()})
    b = OscBundleBuilder(IMMEDIATELY)
    b.add_content(msg("/found", found))
    for name, v in values.items():
        b.add_content(msg("/gesture/" + name, v))
    return b.build().dgram


def w(frame, name):
    return float(frame.weights[INDEX[name]])


def test_first_frame_is_neutral_then_gestures_drive_channels():
    a = FaceOscAdapter()
    f = a.handle(frame_bundle(), 0.0)
    assert w(f, "jawOpen") == 0 and w(f, "eyeBlinkLeft") == 0 and w(f, "mouthSmileLeft") == 0
    assert np.isnan(w(f, "tongueOut"))  # not driven by FaceOSC: missing, not 0
    g = a.handle(frame_bundle(mouth__height=1.0 + 0.5 * SPANS["mouth_height"]), 0.02)
    assert w(g, "jawOpen") == pytest.approx(0.5, abs=0.01)  # the neutral moved ~0.1% in 20 ms
    h = a.handle(frame_bundle(eye__left=2.8 - SPANS["eye_left"]), 0.04)
    # FaceOSC's left eye is the image's left: the subject's right eye.
    assert w(h, "eyeBlinkRight") == pytest.approx(1.0, abs=0.01) and w(h, "eyeBlinkLeft") == 0
    k = a.handle(frame_bundle(mouth__width=15.0, eyebrow__right=8.0), 0.06)
    assert w(k, "mouthSmileLeft") == pytest.approx(0.5, abs=0.01)
    assert w(k, "mouthStretchRight") == pytest.approx(0.15, abs=0.01) and w(k, "mouthPucker") == 0
    assert w(k, "browOuterUpLeft") == pytest.approx(0.5, abs=0.01) and w(k, "browOuterUpRight") == 0
    assert w(k, "browInnerUp") == pytest.approx(0.25, abs=0.01)
    counts(a, datagrams=4, frames=4)


def test_mirrored_swaps_sides():
    a = FaceOscAdapter(mirrored=True)
    a.handle(frame_bundle(), 0.0)
    f = a.handle(frame_bundle(eye__left=2.0), 0.01)
    assert w(f, "eyeBlinkLeft") == pytest.approx(1.0, abs=0.01) and w(f, "eyeBlinkRight") == 0


def test_running_neutral_fades_a_held_expression_and_follows_rest_fast():
    a = FaceOscAdapter()
    a.handle(frame_bundle(), 0.0)
    open_ = 1.0 + SPANS["mouth_height"]
    assert w(a.handle(frame_bundle(mouth__height=open_), 0.1), "jawOpen") == pytest.approx(1.0, abs=0.01)
    held = a.handle(frame_bundle(mouth__height=open_), 0.1 + TAU_ACTIVE)
    assert w(held, "jawOpen") == pytest.approx(math.exp(-1), abs=0.02)  # one slow time constant
    a.handle(frame_bundle(mouth__height=0.5), 30.0)  # closes below the old rest: neutral follows fast
    back = a.handle(frame_bundle(mouth__height=0.5 + 0.25 * SPANS["mouth_height"]), 32.0)
    assert w(back, "jawOpen") == pytest.approx(0.25, abs=0.03)


def test_a_glitch_far_from_the_neutral_restarts_it():
    a = FaceOscAdapter()
    a.handle(frame_bundle(), 0.0)
    glitch = 1.0 + 2 * RESET_SPANS * SPANS["mouth_height"]
    assert w(a.handle(frame_bundle(mouth__height=glitch), 0.01), "jawOpen") == 0  # new neutral there
    a.handle(frame_bundle(mouth__height=1.0), 0.02)  # back: far again, restarts at the true rest
    f = a.handle(frame_bundle(mouth__height=1.0 + 0.5 * SPANS["mouth_height"]), 0.03)
    assert w(f, "jawOpen") == pytest.approx(0.5, abs=0.01)


def test_found_zero_gives_all_nan_weights():
    a = FaceOscAdapter()
    f = a.handle(frame_bundle(found=0, mouth__height=9.0), 0.0)
    assert f is not None and np.isnan(f.weights).all() and f.head_rotation is None
    counts(a, datagrams=1, frames=1)


def test_pose_and_raw():
    a = FaceOscAdapter()
    raw = [float(i) for i in range(132)]
    b = OscBundleBuilder(IMMEDIATELY)
    for m in (msg("/found", 1), msg("/pose/position", 320.0, 240.0), msg("/pose/scale", 4.0),
              msg("/pose/orientation", 0.1, 0.2, 0.3), msg("/raw", *raw)):
        b.add_content(m)
    f = a.handle(b.build().dgram, 0.0)
    np.testing.assert_allclose(f.head_rotation, euler_to_quat(-0.2, 0.1, -0.3), atol=1e-6)
    assert f.markers.shape == (66, 3) and f.markers[1].tolist() == [2.0, 3.0, 0.0]
    assert f.marker_names[0] == "faceosc_0"
    assert a.pose_position == (320.0, 240.0) and a.pose_scale == 4.0
    counts(a, datagrams=1, frames=1)


@pytest.mark.parametrize("message", [
    msg("/found", 1.0), msg("/found"), msg("/found", "yes"),
    msg("/gesture/jaw"), msg("/gesture/mouth/width", "wide"),
    msg("/pose/orientation", 0.1, 0.2), msg("/pose/position", 1.0), msg("/pose/scale", True),
    msg("/raw", *([1.0] * 131)),
])
def test_wrong_types_and_too_few_arguments_are_malformed(message):
    a = FaceOscAdapter()
    b = OscBundleBuilder(IMMEDIATELY)
    b.add_content(message)
    assert a.handle(b.build().dgram, 0.0) is None
    extra = msg("/gesture/jaw", 20.0, "extra")
    assert a.handle(extra.dgram, 0.1) is not None  # an extra argument is ignored
    counts(a, datagrams=2, frames=1, malformed=1)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_nonfinite_rejects_the_frame(bad):
    a = FaceOscAdapter()
    assert a.handle(frame_bundle(jaw=bad), 0.0) is None
    assert a.handle(frame_bundle(), 0.1) is not None
    counts(a, datagrams=2, frames=1, nonfinite=1)


def test_unknown_addresses_and_unparseable_datagrams():
    a = FaceOscAdapter()
    assert a.handle(msg("/gesture/nose", 1.0).dgram, 0.0) is None
    assert a.handle(b"", 0.1) is None
    assert a.handle(frame_bundle()[:-3], 0.2) is None
    counts(a, datagrams=3, unknown_address=1, malformed=2)
