"""The ARKit -> VMC/VRM name tables: perfect-sync spelling, folding a rig's channels, the VRM 0.x presets."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.mapping.vrm_names import (
    PERFECT_SYNC_NAMES,
    VRM0_PRESETS,
    VRM1_FROM_VRM0,
    fold_to_arkit,
    vrm0_from_arkit,
)

K = {name: i for i, name in enumerate(ARKIT_NAMES)}
P = {name: i for i, name in enumerate(VRM0_PRESETS)}


def folded(names, values):
    first, second, extras = fold_to_arkit(names)
    padded = np.append(np.asarray(values, dtype=float), 0.0)
    return np.maximum(padded[first], padded[second]), [names[i] for i in extras]


def test_perfect_sync_names_are_the_52_in_pascal_case():
    assert len(PERFECT_SYNC_NAMES) == len(set(PERFECT_SYNC_NAMES)) == 52
    assert PERFECT_SYNC_NAMES[:2] == ("EyeBlinkLeft", "EyeLookDownLeft")
    assert {"BrowInnerUp", "CheekPuff", "TongueOut", "JawOpen", "MouthSmileRight"} <= set(PERFECT_SYNC_NAMES)


def test_vrm0_presets_and_their_vrm1_names():
    assert set(VRM0_PRESETS) == {"Neutral", "A", "I", "U", "E", "O", "Blink", "Joy", "Angry", "Sorrow", "Fun",
                                 "LookUp", "LookDown", "LookLeft", "LookRight", "Blink_L", "Blink_R"}
    assert set(VRM1_FROM_VRM0) == set(VRM0_PRESETS)
    assert VRM1_FROM_VRM0["Joy"] == "happy" and VRM1_FROM_VRM0["Blink_L"] == "blinkLeft" and VRM1_FROM_VRM0["O"] == "oh"


def test_split_unsided_shapes_fold_by_their_max_and_one_side_alone_is_used():
    arkit, extras = folded(["browInnerUp_L", "browInnerUp_R", "cheekPuffLeft"], [0.2, 0.7, 0.4])
    assert arkit[K["browInnerUp"]] == 0.7 and arkit[K["cheekPuff"]] == 0.4
    assert extras == [] and np.count_nonzero(arkit) == 2


def test_an_unsided_shape_drives_both_sides_and_missing_shapes_are_zero():
    arkit, _ = folded(["eyeBlink", "JawOpen"], [0.6, 0.3])
    assert arkit[K["eyeBlinkLeft"]] == arkit[K["eyeBlinkRight"]] == 0.6 and arkit[K["jawOpen"]] == 0.3
    assert arkit[K["tongueOut"]] == 0 and np.count_nonzero(arkit) == 3


def test_direct_names_in_any_spelling_win_over_folding_and_others_are_extras():
    names = ["browInnerUp", "browInnerUp_L", "mouthLeft", "eyeBlink_R", "PupilDilate_L", "jawOpen", "JawOpen"]
    arkit, extras = folded(names, [0.1, 0.9, 0.3, 0.5, 0.8, 0.25, 0.75])
    assert arkit[K["browInnerUp"]] == 0.1  # the rig's own unsided shape
    assert arkit[K["mouthLeft"]] == 0.3 and arkit[K["eyeBlinkRight"]] == 0.5 and arkit[K["jawOpen"]] == 0.25
    # browInnerUp_L is not ARKit once the unsided shape is there; the second JawOpen is a duplicate, not an extra
    assert extras == ["browInnerUp_L", "PupilDilate_L"]


def test_blinks_split_so_each_eye_closes_as_much_as_arkit_says():
    a = np.zeros(52)
    a[K["eyeBlinkLeft"]], a[K["eyeBlinkRight"]] = 0.9, 0.3
    p = vrm0_from_arkit(a)
    assert p[P["Blink"]] == pytest.approx(0.3)
    assert p[P["Blink"]] + p[P["Blink_L"]] == pytest.approx(0.9) and p[P["Blink_R"]] == 0


@pytest.mark.parametrize("channels, preset, value", [
    ({"jawOpen": 0.8}, "A", 0.8),
    ({"jawOpen": 0.8, "mouthFunnel": 0.4}, "A", 0.6),
    ({"jawOpen": 0.8, "mouthFunnel": 0.4}, "O", 0.4),
    ({"mouthPucker": 0.9, "jawOpen": 0.2}, "U", 0.8),
    ({"mouthStretchLeft": 0.6, "mouthStretchRight": 0.4}, "I", 0.5),
    ({"mouthSmileLeft": 1.0, "mouthSmileRight": 0.5}, "Joy", 0.75),
    ({"browDownLeft": 0.4, "browDownRight": 0.4}, "Angry", 0.4),
    ({"eyeLookOutLeft": 0.6, "eyeLookInRight": 0.4}, "LookLeft", 0.5),
    ({"eyeLookUpLeft": 0.2, "eyeLookUpRight": 0.2}, "LookUp", 0.2),
    ({"mouthPucker": 0.1, "jawOpen": 0.9}, "U", 0.0),  # clipped at 0
])
def test_presets_follow_the_documented_table(channels, preset, value):
    a = np.zeros(52)
    for name, v in channels.items():
        a[K[name]] = v
    assert vrm0_from_arkit(a)[P[preset]] == pytest.approx(value)


def test_presets_are_in_0_1_for_any_input_batched_and_neutral_stays_0():
    a = np.random.default_rng(0).uniform(-2, 3, (100, 52))
    a[0, 3] = np.nan
    p = vrm0_from_arkit(a)
    assert p.shape == (100, 17) and (p >= 0).all() and (p <= 1).all() and (p[:, P["Neutral"]] == 0).all()
    np.testing.assert_allclose(p[5], vrm0_from_arkit(a[5]))
    with pytest.raises(ValueError, match="expected 52 ARKit values, got 51"):
        vrm0_from_arkit(np.zeros(51))
