"""Expression transfer (Shin & Lee §6.2): alignment, nearest vertices, bounded weights, cubic tables."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.geometry import euler_to_quat, quat_to_matrix

from facepuppet.offline.actuation.face_scale import UNCERTAIN_SPREAD, FaceScale, face_scale, face_units
from facepuppet.offline.actuation.shape_choice import observable_shapes
from facepuppet.offline.actuation.transfer import (
    align_markers,
    parameter_shape_pairs,
    read_landmarks,
    read_override,
    retarget_actor,
    s_distribution,
    umeyama,
)
from facepuppet.offline.actuation.transfer_eval import transfer_error
from helpers.small_characters import grid_face

MARKER_VERTICES = np.array([30, 48, 66, 115, 140, 160, 200, 220, 245, 300, 330, 350, 390, 410])


def actor_on(character: Character, names=None, quantiles=None):
    """An actor whose markers sit on the given vertices, seen through a known similarity (scale 1.25).

    names : marker names (default m0, m1, ...); quantiles : (levels, values (L, 2)) stored as s_quantiles
    """
    rot = quat_to_matrix(euler_to_quat(0.1, -0.05, 0.08)).astype(np.float64)
    scale, shift = 1.25, np.array([2.0, 60.0, -1.0])
    to_actor = lambda p: scale * p @ rot.T + shift          # noqa: E731
    neutral = to_actor(character.vertices[MARKER_VERTICES].astype(np.float64))
    dense = character.dense_deltas().astype(np.float64)[:, MARKER_VERTICES]
    cubic = np.zeros((3, 2, len(MARKER_VERTICES), 3))
    cubic[2, 0] = scale * dense[0] @ rot.T                 # actuation 0 is exactly jawOpen
    cubic[2, 1] = scale * dense[1] @ rot.T * 0.5           # actuation 1 is half a puff
    metrics = {} if quantiles is None else {"s_quantiles": {"levels": list(quantiles[0]),
                                                             "values": np.asarray(quantiles[1]).tolist()}}
    lower = np.minimum(-0.2, np.asarray(quantiles[1]).min(axis=0) - 0.2) if quantiles is not None else np.full(2, -0.2)
    actor = Actor(names=tuple(names or (f"m{i}" for i in range(len(MARKER_VERTICES)))), units="cm", neutral=neutral,
                  cubic=cubic, unmixing=np.eye(2), class_axes=np.eye(3)[:2], class_marker=np.arange(2),
                  head_markers=[11, 12, 13], s_lower=lower, s_upper=np.full(2, 1.2),
                  metadata={"metrics": metrics})
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
    sim, vertices, rms, landmark_rms, pairs = align_markers(actor, character, override)
    assert pairs == {} and np.isnan(landmark_rms)
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


@pytest.mark.gl
def test_retarget_actor_command_draws_the_actuations_on_the_face(tmp_path, capsys):
    import argparse

    from PIL import Image

    from facepuppet.offline.actuation import commands as actor_commands
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


QUANTILES = ((0.0, 0.01, 0.5, 0.99, 1.0), [[-0.9, -0.1], [-0.8, 0.0], [0.0, 0.0], [1.0, 0.9], [1.1, 1.0]])


def test_parameter_shape_pairs_cover_the_capture_range_including_negative_s():
    actor, _ = actor_on(grid_face(), quantiles=QUANTILES)
    levels, values, source = s_distribution(actor)
    assert source == "capture quantiles" and values.shape == (5, 2)
    s, disp = parameter_shape_pairs(actor, n_sparse=50, n_dense=50, levels=6)
    alone = s[1:13]                                         # actuation 0 alone, then actuation 1 alone
    np.testing.assert_allclose(alone[:6, 0], np.linspace(-0.8, 1.0, 6))
    np.testing.assert_allclose(alone[6:, 1], np.linspace(0.0, 0.9, 6))
    assert s[:, 0].min() < -0.5 and s[:, 1].min() >= -0.1 and s.max() <= 1.1
    np.testing.assert_allclose(disp[3], actor.evaluate(s[3]) - actor.neutral, atol=1e-5)   # eq 2
    plain, _ = actor_on(grid_face())                         # no stored quantiles: the bounds less the margin
    _, values, source = s_distribution(plain)
    assert source.startswith("bounds") and values[1, 0] == pytest.approx(1.2 - 1.4 / 6)


def test_negative_actuation_drives_the_opposite_shape():
    character = grid_face(extra=True)
    actor, _ = actor_on(character, quantiles=QUANTILES)
    override = {0: int(MARKER_VERTICES[0]), 5: int(MARKER_VERTICES[5]), 9: int(MARKER_VERTICES[9])}
    pair = retarget_actor(actor, character, override=override)
    names = list(character.shape_names)
    up, down = pair.weights([0.8, 0.0]), pair.weights([-0.7, 0.0])
    assert up[names.index("jawOpen")] > 0.6 and up[names.index("jawClose")] < 0.15
    assert down[names.index("jawClose")] > 0.5 and down[names.index("jawOpen")] < 0.15
    # trained on s >= 0 only (the old behaviour), the negative side is an extrapolated guess
    s = np.array([[t, 0.0] for t in np.linspace(0, 1, 9)])
    old = retarget_actor(actor, character, s=s, disp=np.array([actor.evaluate(x) - actor.neutral for x in s]),
                         override=override)
    assert old.weights([-0.7, 0.0])[names.index("jawClose")] < 0.2


def test_unobservable_shapes_are_left_out_unless_included():
    character = grid_face(extra=True)
    actor, _ = actor_on(character)
    left = observable_shapes(character, MARKER_VERTICES, radius=1.0)
    assert left == {"eyeLookIn_L": "excluded by name",
                    "cornerBump": "no marker within 1.00 cm of its region"}
    assert observable_shapes(character, MARKER_VERTICES, 1.0, include=("eyeLook*", "corner*")) == {}
    override = {0: int(MARKER_VERTICES[0]), 5: int(MARKER_VERTICES[5]), 9: int(MARKER_VERTICES[9])}
    pair = retarget_actor(actor, character, override=override)
    cubic = np.abs(pair.cubic).max(axis=(0, 1))
    names = list(character.shape_names)
    assert cubic[names.index("eyeLookIn_L")] == 0 and cubic[names.index("cornerBump")] == 0
    assert pair.metadata["metrics"]["shapes_used"] == 3
    # puff and its gaze-named copy share the work once the copy is included
    both = retarget_actor(actor, character, override=override, include=("eyeLook*",))
    w = both.weights([0.0, 1.0])
    assert w[names.index("puff")] + w[names.index("eyeLookIn_L")] == pytest.approx(0.5, abs=0.05)


LANDMARK_NAMES = {0: "NoseTop", 3: "Reye_Inside", 5: "Leye_Inside", 10: "Mouth_Rend", 12: "Mouth_Lend", 13: "Chin"}


def test_landmark_alignment_and_inner_eye_corner_fapu(tmp_path):
    character = grid_face()
    names = [LANDMARK_NAMES.get(i, f"m{i}") for i in range(len(MARKER_VERTICES))]
    actor, scale = actor_on(character, names=names)
    landmarks = np.zeros(68, dtype=np.int64)
    for i, name in LANDMARK_NAMES.items():
        landmarks[{"NoseTop": 27, "Reye_Inside": 39, "Leye_Inside": 42, "Mouth_Rend": 48, "Mouth_Lend": 54,
                   "Chin": 8}[name]] = MARKER_VERTICES[i]
    align = align_markers(actor, character, landmarks=landmarks)
    assert len(align.landmarks) == 6 and align.landmark_rms < 1e-4 and align.rms < 1e-3
    assert np.cbrt(np.linalg.det(align.similarity[:3, :3])) == pytest.approx(1 / scale, rel=1e-4)
    np.testing.assert_array_equal(align.vertices, MARKER_VERTICES)
    fa, fc, kind = face_units(actor, character, align.vertices, landmarks)
    assert kind == "inner eye corners" and fa == pytest.approx(scale * fc, rel=1e-5)
    path = tmp_path / "vertex_indices.json"
    path.write_text(json.dumps({"idx_to_landmark_verts": landmarks.tolist()}))
    np.testing.assert_array_equal(read_landmarks(path, character.n_vertices), landmarks)
    path.write_text(json.dumps({"idx_to_landmark_verts": [1, 2, 999]}))
    with pytest.raises(ValueError, match=r"vertex_indices\.json: field idx_to_landmark_verts: expected a list"):
        read_landmarks(path, character.n_vertices)


def test_transfer_error_is_small_for_an_exact_pair_and_large_for_the_neutral():
    character = grid_face()
    actor, _ = actor_on(character)
    override = {0: int(MARKER_VERTICES[0]), 5: int(MARKER_VERTICES[5]), 9: int(MARKER_VERTICES[9])}
    pair = retarget_actor(actor, character, override=override)
    fa, fc, _ = face_units(actor, character, pair.marker_vertices, None)
    rng = np.random.default_rng(1)
    s = rng.uniform(0, 0.9, (20, 2))
    frames = np.array([actor.evaluate(x) for x in s])
    e = transfer_error(actor, pair, character, frames, fa, fc)
    assert e["frames"] == 20 and e["solve_rms"] < 0.03
    assert e["transfer_rms"] < 0.2 * e["zero_rms"] and e["oracle_rms"] < 0.2 * e["zero_rms"]
    with pytest.raises(ValueError, match="every shape of 'grid' was left out"):
        retarget_actor(actor, character, override=override, exclude=("*",))


def test_trained_actor_stores_its_actuation_quantiles():
    from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
    from facepuppet.offline.actuation.train import train_actor

    cap, _ = synthetic_capture(n_frames=400, n_markers=12, k=3, seed=2)
    model = train_actor(cap, k=3, head_markers=["M00", "M01", "M02", "M03"])
    levels, values, source = s_distribution(model.actor_)
    assert source == "capture quantiles"
    np.testing.assert_allclose(values, np.quantile(model.s_, levels, axis=0), atol=1e-5)
    s, _ = parameter_shape_pairs(model.actor_, n_sparse=20, n_dense=20)
    assert s.min() >= values[0].min() - 1e-9 and s.max() <= values[-1].max() + 1e-9


def test_face_actuation_cells_count_every_weight_they_show(egl_ctx):
    from facepuppet.offline.actuation.pictures import LABEL_WEIGHT, face_actuation_images

    character = grid_face()
    actor, _ = actor_on(character)
    pair = retarget_actor(actor, character)
    images = face_actuation_images(pair, character, egl_ctx, size=(160, 120))
    assert images[0][0] == "neutral: 0 weights >= 0.1"
    for k, (label, _) in enumerate(images[1:]):
        n = int(np.sum(pair.weights(np.eye(pair.cubic.shape[1])[k]) >= LABEL_WEIGHT))
        assert label.endswith(f": {n} weight{'s' if n != 1 else ''} >= {LABEL_WEIGHT:g}")


def landmark_actor(character: Character, move: dict | None = None):
    """The grid-face actor (scale 1.25) with its six landmark markers named, and the character's landmarks.

    move : {marker name: (fraction, towards name)}: that marker placed off its landmark on the actor, moved that
        fraction of the way towards another marker (its motion unchanged)
    """
    names = [LANDMARK_NAMES.get(i, f"m{i}") for i in range(len(MARKER_VERTICES))]
    actor, scale = actor_on(character, names=names)
    neutral = actor.neutral.astype(np.float64)
    for name, (fraction, towards) in (move or {}).items():
        i, j = names.index(name), names.index(towards)
        neutral[i] += fraction * (neutral[j] - neutral[i])
    actor = dataclasses.replace(actor, neutral=neutral)
    landmarks = np.zeros(68, dtype=np.int64)
    for i, name in LANDMARK_NAMES.items():
        landmarks[LANDMARK_OF[name]] = MARKER_VERTICES[i]
    return actor, scale, landmarks


LANDMARK_OF = {"NoseTop": 27, "Reye_Inside": 39, "Leye_Inside": 42, "Mouth_Rend": 48, "Mouth_Lend": 54, "Chin": 8}


def test_one_marker_off_its_landmark_does_not_scale_the_motion():
    """Reye_Inside placed 30 % of the way towards Leye_Inside: the inner-eye-corner distance alone says the
    character's face is 1/0.7 times larger than it is, and jawOpen at s = 0.8 would come out at 1.0."""
    character = grid_face()
    actor, scale, landmarks = landmark_actor(character, {"Reye_Inside": (0.3, "Leye_Inside")})
    pair = retarget_actor(actor, character, landmarks=landmarks)
    m = pair.metadata["metrics"]
    assert m["fapu_character"] / m["fapu_actor"] == pytest.approx(1 / scale, rel=0.05)
    jaw = pair.weights([0.8, 0.0])[list(character.shape_names).index("jawOpen")]
    assert jaw == pytest.approx(0.8, abs=0.08)


FACE = {"Reye_Inside": (-1.6, 3.0, 0.0), "Leye_Inside": (1.6, 3.0, 0.0), "NoseTop": (0.0, 3.4, 0.3),
        "NoseHead": (0.0, 0.8, 2.0), "Mouth_Rend": (-2.4, -2.0, 0.5), "Mouth_Lend": (2.4, -2.0, 0.5),
        "Mouth_Up": (0.0, -1.5, 1.0), "Mouth_Down": (0.0, -2.6, 0.9), "Chin": (0.0, -5.5, 0.2)}


def test_face_scale_of_a_similar_face_is_its_size_and_sure():
    names = list(FACE)
    character = np.array([FACE[n] for n in names])
    rot = quat_to_matrix(euler_to_quat(0.3, -0.2, 0.1)).astype(np.float64)
    actor = 1.3 * character @ rot.T + [5.0, 1.0, -2.0]
    found = face_scale(actor, character, names)
    assert found.ratio == pytest.approx(1 / 1.3, rel=1e-9) and found.n == 36
    assert found.spread < 1e-9 and not found.uncertain
    assert "warning" not in found.summary() and "median of 36 landmark-distance ratios" in found.summary()
    assert FaceScale.from_dict(json.loads(json.dumps(found.as_dict()))) == found
    assert face_scale(actor[:2], character[:2], names[:2]) is None        # one distance cannot say


def test_face_scale_of_other_proportions_says_it_is_uncertain_and_names_the_disagreeing_landmarks():
    """The actor's face 1.5 times wider than the character's (eyes and mouth), as tall: horizontal
    distances say 1/1.5, vertical ones 1; no ratio serves both."""
    names = list(FACE)
    character = np.array([FACE[n] for n in names])
    actor = character * [1.5, 1.0, 1.0]
    found = face_scale(actor, character, names)
    assert 1 / 1.5 < found.ratio < 1.0 and found.least == pytest.approx(1 / 1.5) and found.most == pytest.approx(1)
    assert found.uncertain and found.spread > UNCERTAIN_SPREAD
    line = found.summary()
    assert "warning: the scale is uncertain" in line and "--face-scale" in line
    smallest, largest = list(found.by_landmark)[0], list(found.by_landmark)[-1]
    assert smallest.startswith("Mouth_") and largest in ("NoseTop", "NoseHead", "Chin", "Mouth_Up", "Mouth_Down")
    assert f"through {smallest} say" in line and f"through {largest} " in line
    # a similar face with its markers a little off their landmarks (1 mm on a 10 cm face) is not called uncertain
    rng = np.random.default_rng(3)
    assert not face_scale(character + rng.normal(0, 0.1, character.shape), character, names).uncertain


def test_a_character_without_shapes_is_refused_with_what_to_do(tmp_path):
    """import-rig of a neutral OBJ alone gives 0 shapes; retarget-actor then says so and how to import it."""
    obj = tmp_path / "face" / "neutral.obj"
    obj.parent.mkdir()
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    character_path = tmp_path / "face.npz"
    imported = subprocess.run([sys.executable, "-m", "facepuppet", "import-rig", str(obj), "-o", str(character_path)],
                              capture_output=True, text=True, timeout=300)
    assert imported.returncode == 0, imported.stderr
    assert "shapes: 0" in imported.stdout and "no expression shapes" in imported.stdout
    actor, _ = actor_on(grid_face())
    done = subprocess.run([sys.executable, "-m", "facepuppet", "retarget-actor", str(actor.save(tmp_path / "a.npz")),
                           str(character_path), "-o", str(tmp_path / "pair.npz")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and not (tmp_path / "pair.npz").exists()
    message = done.stderr
    assert str(character_path) in message and "has no expression shapes" in message, message
    assert "import-rig NEUTRAL.obj SHAPES_FOLDER" in message and "{" not in message   # no bare dict of reasons


def test_every_shape_left_out_counts_the_reasons_and_names_the_options():
    character = grid_face(extra=True)
    actor, _ = actor_on(character)
    override = {0: int(MARKER_VERTICES[0]), 5: int(MARKER_VERTICES[5]), 9: int(MARKER_VERTICES[9])}
    with pytest.raises(ValueError) as refused:
        retarget_actor(actor, character, override=override, exclude=("jaw*", "puff", "eyeLook*"), radius=1.0)
    message = str(refused.value)
    assert "every shape of 'grid' was left out (5 shapes: 4 excluded by name; 1 no marker within " in message
    assert "--include-shapes" in message and "--region-radius" in message


def test_retarget_actor_face_scale_option(tmp_path):
    """--face-scale sets the ratio (the landmarks' own is still printed beside it); a ratio that is not a positive
    number is refused, exit 2, before any work."""
    character = grid_face()
    actor, scale, landmarks = landmark_actor(character)
    (tmp_path / "landmarks.json").write_text(json.dumps(landmarks.tolist()))
    command = [sys.executable, "-m", "facepuppet", "retarget-actor", str(actor.save(tmp_path / "a.npz")),
               str(character.save(tmp_path / "face.npz")), "--landmarks", str(tmp_path / "landmarks.json")]
    done = subprocess.run(command + ["-o", str(tmp_path / "p.npz"), "--face-scale", "0.5"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"face-size ratio 0.500 (given); the landmarks say {1 / scale:.3f}" in done.stdout
    pair = ActorPair.load(tmp_path / "p.npz")
    assert pair.metadata["metrics"]["fapu_character"] / pair.metadata["metrics"]["fapu_actor"] == pytest.approx(0.5)
    for bad in ("-1", "0", "nan"):
        refused = subprocess.run(command + ["-o", str(tmp_path / "q.npz"), "--face-scale", bad], capture_output=True,
                                 text=True, timeout=300)
        assert refused.returncode == 2 and "--face-scale: expected a positive ratio" in refused.stderr
        assert not (tmp_path / "q.npz").exists()
