"""The automatic head-marker choice on takes where a region holds still and the head turns by a known motion.

A still brow or a still jaw is as rigid as the skull; the choice must recover the head motion that was added
(within 0.5 deg over the take) or say that it cannot tell, naming the rival sets, which the test checks are
really rigid, span the face and move differently. Built from both kit takes, with the kit's names and with the names
taken away (then nothing but the motion can tell the skull).
"""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.rigid import kabsch

from conftest import need_shared
from facepuppet.offline.actuation.head_choice import RIVAL_RATIO, SPAN_FRACTION, span_fraction
from facepuppet.offline.actuation.stabilise import RIGID_WARN_MM, rigidity_mm, stabilise
from facepuppet.offline.io.capture import read_capture
from helpers.still_region_takes import BROWS, JAW, rotation_error_deg, still_region_take

TOLERANCE_DEG = 0.5
SCENES = {"brows still": (BROWS, 0.0), "jaw still": (JAW, 0.0), "jaw still on its hinge": (JAW, 1.5)}


def _frame(markers: np.ndarray, head: tuple[int, ...]) -> np.ndarray:
    h = markers[:, list(head)]
    return kabsch(np.broadcast_to(h[0], h.shape), h)[0]


@pytest.mark.data
@pytest.mark.parametrize("named", [True, False], ids=["kit names", "no names"])
@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("take", ["jaw", "cheeks"])
def test_the_found_head_recovers_the_added_rotation_or_names_the_rivals(take, scene, named):
    capture = read_capture(need_shared("markers", f"animface_{take}.trc"))
    still, hinge = SCENES[scene]
    markers, truth = still_region_take(capture, still, turn_deg=4.0, hinge_deg=hinge)
    names = list(capture.names) if named else [f"M{i:02d}" for i in range(capture.n_markers)]
    try:
        out = stabilise(markers, names, mm_per_unit=10.0)
    except UsageError as refusal:
        text = str(refusal)
        assert "ambiguous" in text and "--head-markers" in text, text
        rivals = refusal.candidates
        assert len(rivals) >= 2
        first = rigidity_mm(markers, rivals[0], 10.0)
        assert first <= RIGID_WARN_MM
        for head in rivals:
            assert ", ".join(names[i] for i in head) in text
            assert rigidity_mm(markers, head, 10.0) <= RIVAL_RATIO * first
            assert span_fraction(markers, head) >= SPAN_FRACTION
        # the claim: they move differently, by more than the tolerance
        apart = rotation_error_deg(_frame(markers, rivals[0]), _frame(markers, rivals[1])).max()
        assert apart > TOLERANCE_DEG, apart
        assert not named, f"the kit's names are evidence enough, yet: {text}"
        return
    # a note on a more rigid set that turns apart is a claim too
    for other, apart in out.choice.rivals:
        assert ", ".join(names[i] for i in other) in out.choice.describe(names)
        assert rigidity_mm(markers, other, 10.0) <= out.choice.rigidity_mm
        assert rotation_error_deg(_frame(markers, other), _frame(markers, out.head_markers)).max() == pytest.approx(
            apart, abs=1e-6) and apart > TOLERANCE_DEG
    error = rotation_error_deg(out.rotation, truth).max()
    assert error <= TOLERANCE_DEG, (f"removed a head rotation up to {error:.2f} deg off the added one, with "
                                    f"{[names[i] for i in out.head_markers]}")


@pytest.mark.data
@pytest.mark.parametrize("take", ["cheeks", "jaw"])
def test_given_head_markers_get_their_rigidity_and_the_warning_above_1_mm_from_train_actor(take, tmp_path):
    import subprocess
    import sys

    path = need_shared("markers", f"animface_{take}.trc")
    skull = ["ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop"]
    capture = read_capture(path)
    expected = rigidity_mm(capture.markers, [capture.names.index(n) for n in skull], 10.0)
    done = subprocess.run([sys.executable, "-m", "facepuppet", "train-actor", str(path), "-o", str(tmp_path / "a.npz"),
                           "--k", "4", "--head-markers", *skull], capture_output=True, text=True, timeout=600)
    text = done.stdout + done.stderr
    assert done.returncode == 0, text
    assert f"head markers (given): {', '.join(skull)}; rigidity: distance SD up to {expected:.2f} mm" in text, text
    # the cheeks take's nose bridge slides with the cheeks (1.6 mm); the jaw take's set holds (0.35 mm)
    assert ("warning: not rigid" in text) == (expected > RIGID_WARN_MM), text
    assert (take == "cheeks") == (expected > RIGID_WARN_MM), expected


@pytest.mark.data
def test_train_actor_refuses_an_ambiguous_take_with_exit_2_and_takes_the_named_skull(tmp_path):
    """A jaw held still on its hinge, markers without telling names: the command names both rigid sets and asks
    for --head-markers; given the skull, it trains."""
    import dataclasses
    import subprocess
    import sys

    from facepuppet.offline.io.capture import write_trc

    capture = read_capture(need_shared("markers", "animface_jaw.trc"))
    markers, _ = still_region_take(capture, JAW, hinge_deg=1.5)
    anonymous = tuple(f"M{i:02d}" for i in range(capture.n_markers))
    take = write_trc(tmp_path / "held_jaw.trc", dataclasses.replace(
        capture, markers=markers.astype(np.float32), names=anonymous, source=""))
    command = [sys.executable, "-m", "facepuppet", "train-actor", str(take), "-o", str(tmp_path / "a.npz"), "--k", "3"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "error: head markers: ambiguous: " in done.stderr and "--head-markers" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "a.npz").exists()
    skull = [anonymous[capture.names.index(n)] for n in ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")]
    done = subprocess.run(command + ["--head-markers", *skull], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"head markers (given): {', '.join(skull)}" in done.stderr


def test_names_that_say_skull_and_names_that_only_contain_head():
    from facepuppet.offline.actuation.head_choice import skull_named

    names = ["ForeHead_M", "NoseTop", "NoseHead", "NoseHead_L", "Head_L", "RFHD", "LBHD", "L_Temple", "Chin",
             "Leyebrow_M", "HeadTop", "Nose_Bridge", "Forehead2", "Mouth_Lend", "EyebrowHead"]
    assert [names[i] for i in skull_named(names)] == ["ForeHead_M", "NoseTop", "Head_L", "RFHD", "LBHD", "L_Temple",
                                                      "HeadTop", "Nose_Bridge", "Forehead2"]


@pytest.mark.data
def test_a_brow_cluster_given_as_the_head_is_reported_as_too_narrow():
    from facepuppet.offline.actuation.head_choice import SPAN_FRACTION, describe_given

    capture = read_capture(need_shared("markers", "animface_jaw.trc"))
    brow = [capture.names.index(n) for n in ("Leyebrow_M", "Leyebrow_Inside", "Leyebrow_Outside", "Eyebrow_Center")]
    skull = [capture.names.index(n) for n in ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")]
    narrow, wide = describe_given(capture.markers, brow, 10.0), describe_given(capture.markers, skull, 10.0)
    assert narrow.span < SPAN_FRACTION <= wide.span
    assert "poorly determined" in narrow.describe(capture.names)
    assert "poorly determined" not in wide.describe(capture.names)
