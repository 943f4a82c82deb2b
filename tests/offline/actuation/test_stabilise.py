"""Kabsch and head stabilisation."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.geometry import euler_to_quat, quat_to_matrix

from conftest import need_shared
from facepuppet.offline.actuation.stabilise import find_head_markers, kabsch, stabilise


def test_kabsch_recovers_a_known_rigid_motion():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(6, 3))
    r_true = quat_to_matrix(euler_to_quat(0.3, -0.2, 0.5)).astype(np.float64)
    t_true = np.array([1.0, -2.0, 0.5])
    q = (p - t_true) @ r_true          # q = R^T (p - t): R q + t = p
    r, t = kabsch(p, q)
    np.testing.assert_allclose(r, r_true, atol=1e-6)
    np.testing.assert_allclose(t, t_true, atol=1e-6)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # batched: a stack of frames gives the same per-frame answer
    rb, tb = kabsch(np.stack([p, p]), np.stack([q, p]))
    np.testing.assert_allclose(rb[0], r_true, atol=1e-6)
    np.testing.assert_allclose(rb[1], np.eye(3), atol=1e-9)


def _take():
    rng = np.random.default_rng(1)
    neutral = rng.normal(size=(8, 3)) * 5
    n = 50
    markers = np.repeat(neutral[None], n, axis=0)
    markers[:, 5:, 1] += np.sin(np.linspace(0, 6, n))[:, None] * [1.0, -2.0, 3.0]   # markers 5.. deform
    rot = np.stack([quat_to_matrix(euler_to_quat(0.1 * np.sin(i / 5), 0.05 * i / n, 0.0)) for i in range(n)])
    moved = markers @ np.swapaxes(rot, 1, 2) + np.linspace(0, 1, n)[:, None, None]
    return markers, moved


def test_stabilise_removes_head_motion_and_finds_rigid_markers():
    markers, moved = _take()
    names = [f"m{i}" for i in range(8)]
    assert set(find_head_markers(moved, 4)) <= {0, 1, 2, 3, 4}
    out = stabilise(moved, names, head_markers=["m0", "m1", "m2", "m3"])
    assert not out.head_fixed and out.max_angle_deg > 3
    np.testing.assert_allclose(out.markers, markers, atol=1e-4)   # reference frame 0 has no rotation
    again = stabilise(out.markers, names, head_markers=[0, 1, 2, 3])
    assert again.head_fixed and "already head-fixed" in again.summary()


def test_stabilise_bad_inputs():
    markers, moved = _take()
    with pytest.raises(ValueError, match="no marker named 'nose'"):
        stabilise(moved, [f"m{i}" for i in range(8)], head_markers=["nose", "m1", "m2"])
    with pytest.raises(ValueError, match="at least 3 distinct markers"):
        stabilise(moved, [f"m{i}" for i in range(8)], head_markers=[0, 1])


# The kit's takes are in cm; the data README names the forehead markers + NoseTop as the rigid set
SKULL = ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")
BROW = ("Leyebrow_M", "Leyebrow_Inside", "Leyebrow_Outside", "Eyebrow_Center")
CHEEK_CHIN = ("Lcheek_Up", "Lcheek_Down", "Lcheek_Outside", "Chin")


def _moving_cluster(take, cluster, amplitude_cm, tilt_deg):
    """The take with ``cluster`` made one rigid piece that slides ``amplitude_cm`` up and down on the skull
    and tilts by up to ``tilt_deg`` about its centre.

    In the skull's frame (the README's rigid set) the cluster keeps its shape of frame 0 exactly and moves
    by a known offset, so its mutual distances vary less than any real marker set's; carried back into
    the capture frame with the take's own head motion.
    """
    from facepuppet.offline.io.capture import read_capture

    capture = read_capture(need_shared("markers", f"animface_{take}.trc"))
    m = capture.markers.astype(np.float64)
    ref = stabilise(m, capture.names, head_markers=list(SKULL))
    head = m @ np.swapaxes(ref.rotation, 1, 2) + ref.translation[:, None, :]
    idx = [capture.names.index(n) for n in cluster]
    t = np.arange(len(m)) / capture.rate
    wave = np.sin(2 * np.pi * 0.4 * t)
    shape = head[0, idx] - head[0, idx].mean(axis=0)
    tilt = np.stack([quat_to_matrix(euler_to_quat(np.radians(tilt_deg) * w, 0.0, 0.0)) for w in wave])
    head[:, idx] = (head[0, idx].mean(axis=0) + shape @ np.swapaxes(tilt, 1, 2)
                    + np.c_[np.zeros_like(t), amplitude_cm * wave, np.zeros_like(t)][:, None, :])
    back = (head - ref.translation[:, None, :]) @ ref.rotation   # capture = R^T (head - t)
    return capture, back, idx, ref


@pytest.mark.data
@pytest.mark.parametrize("take, cluster", [("jaw", BROW), ("cheeks", CHEEK_CHIN)])
def test_found_head_markers_are_the_skull_not_a_cluster_that_moves_as_one(take, cluster):
    from facepuppet.offline.actuation.stabilise import AmbiguousHead, choose_head_markers, rigidity_mm

    capture, moved, idx, ref = _moving_cluster(take, cluster, amplitude_cm=0.5, tilt_deg=8.0)
    # without names only the motion can tell: the set found, or the rivals named when the take cannot tell
    # which is the skull, never include the cluster
    try:
        blind = choose_head_markers(moved, 4, mm_per_unit=10.0)
        assert blind.rigid and blind.rigidity_mm < 1.0
        found = [blind.markers]
    except AmbiguousHead as refusal:
        found = list(refusal.candidates)
    for head in found:
        assert not set(head) & set(idx), [capture.names[i] for i in head]
    # with the kit's names (what stabilise and train-actor use): the skull, and the figure it prints is true
    choice = choose_head_markers(moved, 4, mm_per_unit=10.0, names=capture.names)
    assert not set(choice.markers) & set(idx), [capture.names[i] for i in choice.markers]
    assert choice.rigidity_mm == pytest.approx(rigidity_mm(moved, choice.markers, 10.0))
    out = stabilise(moved, capture.names, mm_per_unit=10.0)
    assert out.choice == choice
    # the head motion removed is the skull's (within 0.5 deg in every frame), not the cluster's slide
    turn = out.rotation @ np.swapaxes(ref.rotation, 1, 2)
    assert np.degrees(np.arccos(np.clip((np.trace(turn, axis1=1, axis2=2) - 1) / 2, -1, 1))).max() < 0.5
    assert abs(out.max_angle_deg - ref.max_angle_deg) < 0.5
    text = choice.describe(capture.names)
    assert text.startswith("head markers (found by name): ") and "rigidity: distance SD up to" in text
    # the cheeks take's nose bridge slides with the cheeks (1.6 mm): the README's set is named, and warned about
    assert ("warning: not rigid" in text) == (choice.rigidity_mm > 1.0)


@pytest.mark.data
def test_head_markers_that_are_not_rigid_are_reported_with_a_warning():
    from facepuppet.offline.actuation.stabilise import RIGID_WARN_MM, choose_head_markers
    from facepuppet.offline.io.capture import read_capture

    capture = read_capture(need_shared("markers", "animface_jaw.trc"))
    noisy = capture.markers + np.random.default_rng(0).normal(scale=0.15, size=capture.markers.shape)  # 1.5 mm
    choice = choose_head_markers(noisy, 4, mm_per_unit=10.0)
    # two markers each jittered by 1.5 mm per axis: their distance varies by about 1.5 * sqrt(2) mm
    assert choice.rigidity_mm > RIGID_WARN_MM and not choice.rigid
    assert "warning: not rigid" in choice.describe(capture.names) and "--head-markers" in choice.describe(capture.names)


def test_the_summary_gives_the_residual_in_millimetres_for_any_capture_unit():
    # It printed "0.0123 units" whatever the capture was in; the same take in cm and in mm must
    # report the same residual in mm.
    _, moved = _take()
    noisy = moved + np.random.default_rng(2).normal(scale=0.01, size=moved.shape)
    names = [f"m{i}" for i in range(8)]
    in_mm = stabilise(noisy, names, head_markers=[0, 1, 2, 3], mm_per_unit=1.0)
    in_cm = stabilise(noisy / 10.0, names, head_markers=[0, 1, 2, 3], mm_per_unit=10.0)
    expected = f"{in_mm.rms_residual:.3f} mm"
    assert expected in in_mm.summary() and expected in in_cm.summary()
    assert "units" not in in_cm.summary()
