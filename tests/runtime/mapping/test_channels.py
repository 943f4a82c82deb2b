"""One explicit mapping between channel-naming conventions."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import (
    ARKIT_NAMES,
    CHANNEL_REGIONS,
    ChannelMap,
    canonical,
    filter_region,
    gesture_group,
    pascal,
)

# The ICT-FaceKit rig's own spellings (vertex_indices.json "expressions"), written out here
# so the test does not depend on the data kit.
ICT_NAMES = (
    "browDown_L browDown_R browInnerUp_L browInnerUp_R browOuterUp_L browOuterUp_R cheekPuff_L "
    "cheekPuff_R cheekSquint_L cheekSquint_R eyeBlink_L eyeBlink_R eyeLookDown_L eyeLookDown_R "
    "eyeLookIn_L eyeLookIn_R eyeLookOut_L eyeLookOut_R eyeLookUp_L eyeLookUp_R eyeSquint_L eyeSquint_R "
    "eyeWide_L eyeWide_R jawForward jawLeft jawOpen jawRight mouthClose mouthDimple_L mouthDimple_R "
    "mouthFrown_L mouthFrown_R mouthFunnel mouthLeft mouthLowerDown_L mouthLowerDown_R mouthPress_L "
    "mouthPress_R mouthPucker mouthRight mouthRollLower mouthRollUpper mouthShrugLower mouthShrugUpper "
    "mouthSmile_L mouthSmile_R mouthStretch_L mouthStretch_R mouthUpperUp_L mouthUpperUp_R "
    "noseSneer_L noseSneer_R"
).split()


@pytest.mark.parametrize(
    "spelling, key",
    [
        ("eyeBlinkLeft", "eyeBlinkLeft"),
        ("EyeBlinkLeft", "eyeBlinkLeft"),
        ("eyeBlink_L", "eyeBlinkLeft"),
        ("eyeBlink_R", "eyeBlinkRight"),
        ("JawOpen", "jawOpen"),
        ("jawOpen", "jawOpen"),
        ("MouthLeft", "mouthLeft"),  # a direction, not a side
        ("jawRight", "jawRight"),
        ("mouthPucker", "mouthPucker"),  # ends in r, is not a side
        ("browInnerUp_L", "browInnerUpLeft"),
        ("cheekPuff_R", "cheekPuffRight"),
        ("TongueOut", "tongueOut"),
        ("mouthSmile_L", "mouthSmileLeft"),
    ],
)
def test_canonical_keys(spelling, key):
    assert canonical(spelling) == key


def test_every_arkit_name_is_its_own_key_and_survives_pascal_case():
    for name in ARKIT_NAMES:
        assert canonical(name) == name
        assert canonical(pascal(name)) == name
    assert len(set(ARKIT_NAMES)) == 52
    assert pascal("eyeBlink_L") == "EyeBlinkLeft"


def test_arkit_onto_ict_covers_every_ict_shape():
    pascal_names = [pascal(n) for n in ARKIT_NAMES]
    cmap = ChannelMap.build(pascal_names, ICT_NAMES)
    assert cmap.undriven_target == ()
    assert cmap.unmatched_source == ("TongueOut",)  # the ICT rig has no tongue shape
    source = np.zeros(52, np.float32)
    source[pascal_names.index("JawOpen")] = 0.7
    source[pascal_names.index("BrowInnerUp")] = 0.4
    source[pascal_names.index("EyeBlinkLeft")] = 1.0
    target = dict(zip(ICT_NAMES, cmap.apply(source)))
    assert target["jawOpen"] == pytest.approx(0.7)
    assert target["browInnerUp_L"] == pytest.approx(0.4)  # unsided source splits onto both sides
    assert target["browInnerUp_R"] == pytest.approx(0.4)
    assert target["eyeBlink_L"] == 1.0 and target["eyeBlink_R"] == 0.0
    assert sum(v != 0 for v in target.values()) == 4


def test_sided_sources_average_onto_an_unsided_rig_shape():
    cmap = ChannelMap.build(["cheekPuff_L", "cheekPuff_R", "jawOpen"], ["cheekPuff", "jawOpen"])
    np.testing.assert_allclose(cmap.apply(np.array([1.0, 0.5, 0.2])), [0.75, 0.2])
    assert cmap.unmatched_source == () and cmap.undriven_target == ()


def test_missing_channels_are_reported_not_dropped_silently():
    cmap = ChannelMap.build(["JawOpen", "HeadYaw", "Joy"], ["jawOpen", "eyeBlink_L"])
    report = cmap.report()
    assert "HeadYaw" in report and "Joy" in report and "eyeBlink_L" in report
    assert cmap.unmatched_source == ("HeadYaw", "Joy")
    assert cmap.undriven_target == ("eyeBlink_L",)


def test_nan_source_values_drive_nothing():
    cmap = ChannelMap.build(["jawOpen", "eyeBlinkLeft"], ["jawOpen", "eyeBlink_L"])
    np.testing.assert_array_equal(cmap.apply(np.array([np.nan, 0.5])), [0.0, 0.5])


def test_dense_map_equals_a_loop_over_names():
    """The matrix form against the obvious per-name loop, on the full ARKit -> ICT case."""
    src = [pascal(n) for n in ARKIT_NAMES]
    cmap = ChannelMap.build(src, ICT_NAMES)
    rng = np.random.default_rng(0)
    values = rng.random(len(src)).astype(np.float32)
    by_key = {canonical(n): v for n, v in zip(src, values)}
    expected = []
    for name in ICT_NAMES:
        key = canonical(name)
        if key in by_key:
            expected.append(by_key[key])
        else:  # split unsided: browInnerUpLeft <- browInnerUp
            expected.append(by_key[key.removesuffix("Left").removesuffix("Right")])
    np.testing.assert_allclose(cmap.apply(values), expected, rtol=1e-6)


def test_filter_regions_and_gesture_groups_of_channels():
    names = ("EyeBlinkLeft", "browInnerUp", "jawOpen", "mouthSmile_L", "noseSneerLeft", "cheekPuff", "tongueOut",
             "lipSuck_L")
    assert [filter_region(n) for n in names] == ["eyes", "brows", "mouth", "mouth", "other", "mouth", "mouth", "mouth"]
    assert [gesture_group(n) for n in names] == ["eyes", "brows", "lips", "lips", "rest", "rest", "rest", "rest"]


def test_the_two_groupings_differ_only_on_cheeks_lips_and_tongue():
    same = ({"eyes"}, {"brows"}, {"mouth", "lips"}, {"other", "rest"})
    differ = {canonical(n) for n in ARKIT_NAMES if {filter_region(n), gesture_group(n)} not in same}
    assert differ == {"cheekPuff", "cheekSquintLeft", "cheekSquintRight", "tongueOut"}
    assert {prefix for prefix, region, group in CHANNEL_REGIONS if (region, group) == ("mouth", "rest")} == {
        "cheek", "lip", "tongue"}


def test_a_map_onto_the_same_names_copies_and_matches_the_matrix_product():
    names = ("jawOpen", "eyeBlinkLeft", "browInnerUp")
    same = ChannelMap.build(names, names)
    assert same.identity and not ChannelMap.build(names, names[::-1]).identity
    assert not ChannelMap.build(("eyeBlinkLeft", "eyeBlinkRight"), ("eyeBlink",)).identity
    values = np.array([0.3, np.nan, -0.25], np.float32)
    out = np.full(3, 7.0, np.float32)
    assert same.apply(values, out=out) is out
    np.testing.assert_array_equal(out, same.matrix @ np.nan_to_num(values))  # the copy is the product
    np.testing.assert_array_equal(same.apply(values), np.array([0.3, 0.0, -0.25], np.float32))
