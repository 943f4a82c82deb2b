"""The procedural demo head: size, shapes under ARKit names, sides, mouth, lids, file round trip."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.demo import head_parts as parts
from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.geometry import vertex_normals


@pytest.fixture(scope="module")
def head() -> Character:
    return build_demo_character()


def _delta(ch: Character, name: str) -> np.ndarray:
    return ch.dense_deltas()[ch.shape_names.index(name)]


def test_size_and_units(head):
    assert head.n_vertices >= 5000
    assert head.units == "cm"
    lo, hi = head.vertices.min(axis=0), head.vertices.max(axis=0)
    assert 14.0 < hi[0] - lo[0] < 18.0  # head width
    assert 9.0 < hi[1] < 13.0  # crown above the eyes
    assert hi[2] > 10.0 and lo[2] < -8.0  # nose in front (+z), skull behind
    assert head.metadata["settings"] == {"generator": "facepuppet demo head", "version": 1}


def test_shapes_are_arkit_names(head):
    assert len(head.shape_names) >= 16
    assert len(set(head.shape_names)) == len(head.shape_names)
    assert set(head.shape_names) <= set(ARKIT_NAMES)
    for name in ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft", "mouthSmileRight", "browInnerUp"):
        assert name in head.shape_names
    for s in range(head.n_shapes):  # every shape moves something
        assert head.shape_slice(s).stop > head.shape_slice(s).start, head.shape_names[s]


@pytest.mark.parametrize("base", ["eyeBlink", "mouthSmile", "browOuterUp", "eyeWide", "mouthFrown"])
def test_left_is_the_characters_left(head, base):
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        d = np.linalg.norm(_delta(head, base + side), axis=1)
        moved = d > 1e-3
        assert sign * head.vertices[moved, 0].mean() > 0.5, base + side
        assert sign * head.vertices[np.argmax(d), 0] > 0, base + side


def test_jaw_open_parts_the_lips(head):
    # the lip slit: coincident vertices at the front of the mouth, on the midline
    v = head.vertices
    near_mouth = (np.abs(v[:, 0]) < 0.2) & (np.abs(v[:, 1] - parts.MOUTH_Y) < 1.0)
    keys, inverse, counts = np.unique(np.round(v[near_mouth], 5), axis=0, return_inverse=True, return_counts=True)
    shared = np.flatnonzero(counts >= 2)
    front = shared[np.argmax(keys[shared, 2])]
    group = np.flatnonzero(near_mouth)[inverse.reshape(-1) == front]
    opened = v[group] + _delta(head, "jawOpen")[group]
    gap = np.linalg.norm(opened[:, None] - opened[None], axis=-1).max()
    assert gap > 1.0
    drop = v[group, 1] - opened[:, 1]
    assert drop.max() > 1.0 and drop.min() < 0.1  # the lower lip goes down, the upper stays


def test_blink_closes_the_eye(head):
    eye = parts.eye_centre(1.0)
    d = _delta(head, "eyeBlinkLeft")
    moved = np.linalg.norm(d, axis=1) > 1e-4
    v = head.vertices.astype(np.float64)
    lid = moved & (np.abs(v[:, 0] - eye[0]) < 0.3) & (v[:, 2] > eye[2]) & (v[:, 1] > eye[1])
    assert lid.sum() >= 3
    drop = v[lid, 1].min() - (v[lid] + d[lid])[:, 1].min()
    margin = parts.EYE_RADIUS + 0.035
    opening = margin * (np.sin(parts.LID_UPPER) - np.sin(parts.LID_LOWER))
    assert 0.8 * opening < drop < 1.3 * opening


def test_neutral_triangles_are_sound(head):
    t = head.triangles.astype(np.int64)
    assert np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2]))
    v = head.vertices.astype(np.float64)[t]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert area.min() > 1e-5  # cm^2
    normals = vertex_normals(head.vertices, head.triangles)
    # counter-clockwise from outside: the crown faces up, the nose tip forward, the eyeball out
    assert normals[np.argmax(head.vertices[:, 1]), 1] > 0.9
    assert normals[np.argmax(head.vertices[:, 2]), 2] > 0.5
    eye = parts.eye_centre(1.0)
    on_eye = np.abs(np.linalg.norm(head.vertices - eye, axis=1) - parts.EYE_RADIUS) < 1e-4
    assert on_eye.sum() > 100
    assert np.all(np.sum(normals[on_eye] * (head.vertices[on_eye] - eye), axis=1) > 0)


def test_materials_and_colours(head):
    assert {"skin", "lips", "eye", "teeth", "mouth"} <= set(head.material_names)
    used = set(np.unique(head.triangle_material).tolist())
    assert used == set(range(len(head.material_names)))
    assert head.vertex_color.min() >= 0 and head.vertex_color.max() <= 1


def test_normal_deltas_match_vertex_normals(head):
    base = vertex_normals(head.vertices, head.triangles)
    positions, normals = head.dense_deltas(), head.dense_deltas(normals=True)
    for s, name in enumerate(head.shape_names):
        expected = vertex_normals(head.vertices + positions[s], head.triangles) - base
        np.testing.assert_allclose(normals[s], expected, atol=2e-6, err_msg=name)


def test_deterministic(head):
    again = build_demo_character()
    for name, arr in head._arrays().items():
        np.testing.assert_array_equal(arr, again._arrays()[name], err_msg=name)
    assert again.shape_names == head.shape_names


def test_save_load_round_trip(head, tmp_path):
    path = head.save(tmp_path / "demo.npz")
    loaded = Character.load(path)
    assert loaded.shape_names == head.shape_names
    assert loaded.material_names == head.material_names
    assert loaded.units == "cm"
    assert loaded.metadata["settings"]["generator"] == "facepuppet demo head"
    for name, arr in head._arrays().items():
        np.testing.assert_array_equal(getattr(loaded, name), arr, err_msg=name)
