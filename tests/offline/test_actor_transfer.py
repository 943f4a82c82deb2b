"""Expression transfer (Shin & Lee §6.2): alignment, nearest vertices, bounded weights, cubic tables."""

from __future__ import annotations

import json

import numpy as np
import pytest

from facepuppet.offline.actor_transfer import align_markers, read_override, retarget_actor, umeyama
from facepuppet.runtime.actor import Actor
from facepuppet.runtime.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.geometry import euler_to_quat, quat_to_matrix, vertex_normals


def grid_face() -> Character:
    """A gently curved 21 x 21 sheet facing +z, cm, with shapes jawOpen (lower half drops) and puff (+z)."""
    x, y = np.meshgrid(np.linspace(-5, 5, 21), np.linspace(-7, 7, 21))
    v = np.c_[x.ravel(), y.ravel(), 3.0 - 0.04 * (x.ravel() ** 2 + y.ravel() ** 2)].astype(np.float32)
    idx = np.arange(441).reshape(21, 21)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.r_[np.c_[a, b, d], np.c_[a, d, c]].astype(np.uint32)
    if vertex_normals(v, tris)[220, 2] < 0:
        tris = tris[:, ::-1].copy()
    jaw = np.zeros_like(v)
    jaw[:, 1] = np.where(v[:, 1] < 0, 0.1 * v[:, 1], 0.0)
    puff = np.zeros_like(v)
    puff[:, 2] = 0.5 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 8)
    dense = np.stack([jaw, puff])
    offsets, indices, both = sparse_deltas(np.concatenate([dense, np.zeros_like(dense)], axis=2), tolerance=1e-7)
    return Character(name="grid", units="cm", vertices=v, triangles=tris,
                     triangle_material=np.zeros(len(tris), np.uint16), vertex_color=np.full((441, 3), 0.5, np.float32),
                     material_names=("skin",), material_params=np.array([[0.1, 10, MATERIAL_KINDS["skin"], 0]], np.float32),
                     pivot=np.zeros(3, np.float32), shape_names=("jawOpen", "puff"), delta_offsets=offsets,
                     delta_indices=indices, delta_positions=np.ascontiguousarray(both[:, :3]),
                     delta_normals=np.ascontiguousarray(both[:, 3:]))


MARKER_VERTICES = np.array([30, 48, 66, 115, 140, 160, 200, 220, 245, 300, 330, 350, 390, 410])


def actor_on(character: Character):
    """An actor whose markers sit on the given vertices, seen through a known similarity (scale 1.25)."""
    rot = quat_to_matrix(euler_to_quat(0.1, -0.05, 0.08)).astype(np.float64)
    scale, shift = 1.25, np.array([2.0, 60.0, -1.0])
    to_actor = lambda p: scale * p @ rot.T + shift          # noqa: E731
    neutral = to_actor(character.vertices[MARKER_VERTICES].astype(np.float64))
    dense = character.dense_deltas().astype(np.float64)[:, MARKER_VERTICES]
    cubic = np.zeros((3, 2, len(MARKER_VERTICES), 3))
    cubic[2, 0] = scale * dense[0] @ rot.T                 # actuation 0 is exactly jawOpen
    cubic[2, 1] = scale * dense[1] @ rot.T * 0.5           # actuation 1 is half a puff
    actor = Actor(names=tuple(f"m{i}" for i in range(len(MARKER_VERTICES))), units="cm", neutral=neutral,
                  cubic=cubic, unmixing=np.eye(2), class_axes=np.eye(3)[:2], class_marker=np.arange(2),
                  head_markers=np.arange(3), s_lower=np.full(2, -0.2), s_upper=np.full(2, 1.2))
    return actor, scale


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(10, 3))
    r = quat_to_matrix(euler_to_quat(0.4, 0.1, -0.3)).astype(np.float64)
    q = 0.7 * p @ r.T + [1, 2, 3]
    m = umeyama(p, q)
    np.testing.assert_allclose(m[:3, :3], 0.7 * r, atol=1e-9)
    np.testing.assert_allclose(m[:3, 3], [1, 2, 3], atol=1e-9)


def test_alignment_finds_the_marker_vertices_and_transfer_maps_s_to_weights(tmp_path):
    character = grid_face()
    actor, scale = actor_on(character)
    override = {0: int(MARKER_VERTICES[0]), 5: int(MARKER_VERTICES[5]), 9: int(MARKER_VERTICES[9])}
    sim, vertices, rms = align_markers(actor, character, override)
    np.testing.assert_array_equal(vertices, MARKER_VERTICES)
    assert np.cbrt(np.linalg.det(sim[:3, :3])) == pytest.approx(1 / scale, rel=1e-3) and rms < 1e-3
    pair = retarget_actor(actor, character, override=override)
    np.testing.assert_allclose(pair.weights([1.0, 0.0]), [1.0, 0.0], atol=0.05)
    np.testing.assert_allclose(pair.weights([0.0, 1.0]), [0.0, 0.5], atol=0.05)
    np.testing.assert_allclose(pair.weights([0.5, 0.6]), [0.5, 0.3], atol=0.05)
    assert pair.shape_names == ("jawOpen", "puff") and pair.marker_names == actor.names


def test_override_file_is_checked(tmp_path):
    character = grid_face()
    actor, _ = actor_on(character)
    path = tmp_path / "override.json"
    path.write_text(json.dumps({"m0": 30, "nose": 4}))
    with pytest.raises(ValueError, match=r"override\.json: field 'nose': no such actor marker"):
        read_override(path, actor.names, character.n_vertices)
    path.write_text(json.dumps({"m0": 99999}))
    with pytest.raises(ValueError, match=r"field 'm0': expected a vertex index 0\.\.440"):
        read_override(path, actor.names, character.n_vertices)
    path.write_text(json.dumps({"m0": 30}))
    assert read_override(path, actor.names, character.n_vertices) == {0: 30}


def test_retarget_actor_command_draws_the_actuations_on_the_face(tmp_path, capsys):
    import argparse

    from PIL import Image

    from facepuppet.offline import actor_commands

    character = grid_face()
    actor, _ = actor_on(character)
    parser = argparse.ArgumentParser()
    actor_commands.register(parser.add_subparsers())
    args = parser.parse_args(["retarget-actor", str(actor.save(tmp_path / "actor.npz")),
                              str(character.save(tmp_path / "face.npz")), "-o", str(tmp_path / "pair.npz"),
                              "--pictures", str(tmp_path / "pics")])
    assert args.func(args) == 0
    assert "face_actuations.png" in capsys.readouterr().out
    sheet = np.asarray(Image.open(tmp_path / "pics" / "face_actuations.png").convert("RGB")).astype(int)
    cell_w, cell_h = 320, 320 + 18                          # neutral, s01, s02 in one row, labels underneath
    assert sheet.shape == (cell_h, 5 * cell_w, 3)                # 5 columns
    neutral, jaw, puff = (sheet[:320, c * cell_w:(c + 1) * cell_w] for c in range(3))
    assert np.abs(jaw - neutral).mean() > 2                 # the jaw drops visibly
    assert np.abs(puff - neutral).max() > 3                 # the puff (towards the camera) changes the shading
