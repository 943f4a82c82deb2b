"""Look-at: range maps and VRM 0.x curves, the gaze read from eye-look channels, and an expression-type look-at
driving the Look* expressions through its maps (the bone type is drawn in
tests/runtime/render/test_look_at_render.py)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.mapping.expressions import make_drive
from facepuppet.runtime.model.look_at import GAZE_CHANNELS, Gaze, RangeMap, look_at_of

from helpers.vrm_characters import preset_character


def range_map(input_max=90.0, output_scale=1.0, curve=()):
    return {"input_max": input_max, "output_scale": output_scale, "curve": [list(k) for k in curve]}


def look_at_settings(kind="expression", **maps):
    names = ("horizontal_inner", "horizontal_outer", "vertical_down", "vertical_up")
    return {"look_at": {"type": kind, **{n: maps.get(n, range_map()) for n in names},
                        "left_eye": -1, "right_eye": -1}}


def test_a_range_map_is_linear_up_to_its_input_and_flat_after():
    m = RangeMap(20.0, 10.0, np.zeros((0, 4)))
    assert m(5.0) == pytest.approx(2.5) and m(-5.0) == pytest.approx(2.5) and m(40.0) == pytest.approx(10.0)


def test_vrm0_curves_are_unity_hermite_keys():
    # the VRM 0.x default curve (0, 0, 0, 1), (1, 1, 1, 0) is linear with tangents 1 at both ends
    linear = RangeMap(90.0, 10.0, np.array([[0, 0, 0, 1], [1, 1, 1, 0]], float))
    assert linear(45.0) == pytest.approx(5.0)
    # Godette's lookAtHorizontalOuter: the keys' values at their times, a Hermite blend between them
    keys = np.array([[0, 0.05, 0, 0], [0.656278551, 0.393769681, 1.224509, 1.224509], [1, 1.05, 1, 1]])
    m = RangeMap(90.0, 1.0, keys)
    assert m(0.656278551 * 90) == pytest.approx(0.393769681)
    assert m(90.0) == pytest.approx(1.05)
    s, dt = 0.5, 0.656278551
    hermite = ((2 * s**3 - 3 * s**2 + 1) * 0.05 + (-2 * s**3 + 3 * s**2) * 0.393769681
               + (s**3 - s**2) * dt * 1.224509)
    assert m(0.5 * dt * 90) == pytest.approx(hermite)


def test_gaze_reads_eye_angles_at_the_adapters_scale():
    channels = ("jawOpen", "EyeLookOutLeft", "eyeLookIn_R", "eyeLookUpLeft", "eyeLookDownRight")
    g = Gaze(channels)
    yaw_l, pitch_l, yaw_r, pitch_r = g.angles(np.array([0.3, 0.5, 0.25, 0.2, np.nan], np.float32))
    assert (yaw_l, pitch_l, yaw_r, pitch_r) == pytest.approx((15.0, 6.0, 7.5, 0.0))
    assert not Gaze(("jawOpen",)).available


def test_expression_look_at_drives_look_expressions_through_its_maps():
    c = preset_character()
    settings = look_at_settings(horizontal_outer=range_map(20.0, 1.0), vertical_up=range_map(10.0, 0.5))
    look = look_at_of(settings, 0)
    drive = make_drive(c.shape_names, c.expressions, look_at=look)
    m = drive.build(GAZE_CHANNELS)
    values = dict.fromkeys(GAZE_CHANNELS, 0.0)
    values.update(eyeLookOutLeft=0.5, eyeLookInRight=0.5, eyeLookUpLeft=0.1, eyeLookUpRight=0.1)
    m.apply(np.array([values[n] for n in GAZE_CHANNELS], np.float32))
    e = dict(zip(drive.expression_names, m.expression_values.tolist()))
    # 15° to the avatar's left through 20° -> 1: 0.75 (the default preset mapping would give 0.5); 3° up
    # through 10° -> 0.5: 0.15
    assert e["LookLeft"] == pytest.approx(0.75) and e["LookRight"] == 0.0
    assert e["LookUp"] == pytest.approx(0.15) and e["LookDown"] == 0.0
    without = make_drive(c.shape_names, c.expressions).build(GAZE_CHANNELS)
    without.apply(np.array([values[n] for n in GAZE_CHANNELS], np.float32))
    assert dict(zip(drive.expression_names, without.expression_values.tolist()))["LookLeft"] == pytest.approx(0.5)


@pytest.mark.parametrize("change,field", [
    (lambda s: s["look_at"].update(type="eyes"), "settings.look_at.type"),
    (lambda s: s["look_at"]["vertical_up"].update(input_max=0), "settings.look_at.vertical_up.input_max"),
    (lambda s: s["look_at"]["vertical_up"].update(curve=[[1, 0, 0, 0], [0, 1, 0, 0]]),
     "settings.look_at.vertical_up.curve"),
    (lambda s: s["look_at"].update(left_eye=7), "settings.look_at.left_eye"),
])
def test_bad_look_at_tables_are_refused_naming_the_field(change, field):
    settings = look_at_settings()
    change(settings)
    with pytest.raises(TablesError, match=field):
        look_at_of(settings, 3)
