"""``fit-elastic`` and ``clone-elastic`` on small meshes; inner-lip order and lip-line cutting."""

import argparse

import numpy as np
import pytest

from facepuppet.runtime.elastic.model import ElasticModel

from facepuppet.offline.elastic import commands as elastic_commands
from facepuppet.offline.elastic.basis import ElasticBasis, fixed_region
from facepuppet.offline.elastic.clone import character_with_shapes, mesh_character
from facepuppet.offline.elastic.control_points import ControlPoints, write_control_points
from facepuppet.offline.elastic.lip_line import cut_lip_line, fix_inner_lips
from helpers.elastic_meshes import grid, nearest

SPOTS = {
    "nose_tip": (0, 0), "forehead": (0, 2.5), "eye_inner_L": (0.9, 1.3), "eye_inner_R": (-0.9, 1.3),
    "eye_outer_L": (2.0, 1.3), "eye_outer_R": (-2.0, 1.3), "mouth_corner_L": (1.2, -1.6),
    "mouth_corner_R": (-1.2, -1.6), "lip_upper_inner": (0, -1.2), "lip_lower_inner": (0, -2.0),
    "chin": (0, -2.9), "jaw_chin_L": (1.1, -2.7), "jaw_chin_R": (-1.1, -2.7), "lip_lower": (0, -2.3),
    # the points the default muscles hang from
    "cheekbone_L": (1.9, 0.3), "cheekbone_R": (-1.9, 0.3), "forehead_L": (1.2, 2.5), "forehead_R": (-1.2, 2.5),
    "brow_mid_L": (1.3, 1.9), "brow_mid_R": (-1.3, 1.9), "brow_inner_L": (0.6, 1.9), "brow_inner_R": (-0.6, 1.9),
    "nose_root": (0, 1.3), "lip_upper_L": (0.6, -1.1), "lip_upper_R": (-0.6, -1.1),
}


def cli(*argv) -> int:
    parser = argparse.ArgumentParser()
    elastic_commands.register(parser.add_subparsers())
    args = parser.parse_args([str(a) for a in argv])
    return args.func(args)


def grid_points(v) -> ControlPoints:
    return ControlPoints(tuple(SPOTS), np.array([nearest(v, *xy) for xy in SPOTS.values()], np.int64))


def test_fit_then_clone_commands_recover_known_parameters(tmp_path):
    v, tris = grid(17)
    points = grid_points(v)
    fixed = fixed_region(v, v[points.vertex("nose_tip")], v[points.vertex("forehead")], 1.4)
    basis = ElasticBasis().fit(v, tris, points.vertices, fixed)
    truth = np.random.default_rng(5).normal(0, 0.1, (2, len(points.names), 3))
    shapes = {name: basis.displace(u, compact=True) for name, u in zip(("smile", "open"), truth)}
    character = character_with_shapes(mesh_character(v, tris, "grid"), shapes)
    character.save(tmp_path / "grid.npz")
    write_control_points(tmp_path / "points.json", points)
    assert cli("fit-elastic", tmp_path / "grid.npz", "-o", tmp_path / "e.npz", "--controls", tmp_path / "points.json",
               "--fixed-ratio", 1.4) == 0
    model = ElasticModel.load(tmp_path / "e.npz")
    assert model.shape_names == ("smile", "open") and model.control_names == points.names
    np.testing.assert_allclose(model.arrays["params"], truth, atol=1e-3)  # eq. 6 recovers the displacements
    # Clone onto the same mesh moved by a similarity: the cloned shapes are the scaled, moved originals.
    target = mesh_character(2.0 * v + [1.0, -2.0, 0.5], tris, "big")
    target.save(tmp_path / "big.npz")
    assert cli("clone-elastic", tmp_path / "e.npz", tmp_path / "big.npz", "-o", tmp_path / "c.npz",
               "--correspondences", tmp_path / "points.json", "--fixed-ratio", 1.4) == 0
    cloned = ElasticModel.load(tmp_path / "c.npz")
    np.testing.assert_allclose(cloned.arrays["params"], 2.0 * model.arrays["params"], atol=1e-4)
    # The same topology (the source's vertex count: a variant of the rig) needs no correspondences: each
    # control point stays on its vertex, which is what points.json says here.
    assert cli("clone-elastic", tmp_path / "e.npz", tmp_path / "big.npz", "-o", tmp_path / "d.npz",
               "--fixed-ratio", 1.4) == 0
    same = ElasticModel.load(tmp_path / "d.npz")
    np.testing.assert_allclose(same.arrays["params"], cloned.arrays["params"], atol=1e-6)
    v2, tris2 = grid(13)                           # another topology, no built-in proposal: named, exit 2
    mesh_character(v2, tris2, "other").save(tmp_path / "other.npz")
    with pytest.raises(ValueError, match=r"other\.npz has 169 vertices, not the source's 289.*--correspondences"):
        cli("clone-elastic", tmp_path / "e.npz", tmp_path / "other.npz", "-o", tmp_path / "o.npz")


def test_fit_command_needs_controls_or_landmarks(tmp_path):
    v, tris = grid(9)
    mesh_character(v, tris, "grid").save(tmp_path / "g.npz")
    with pytest.raises(ValueError, match=r"g\.npz has no landmarks: give --controls FILE or --landmarks"):
        cli("fit-elastic", tmp_path / "g.npz", "-o", tmp_path / "e.npz")


def test_inner_lips_keep_their_order_on_a_closed_mouth():
    v, tris = grid(21)
    points = grid_points(v)
    names = list(points.names)
    swapped = points.vertices.copy()
    up, low = names.index("lip_upper_inner"), names.index("lip_lower_inner")
    swapped[up], swapped[low] = swapped[low], swapped[up]  # what the nearest-point proposal did on a closed mouth
    fixed = fix_inner_lips(ControlPoints(points.names, swapped), v, tris, np.arange(len(v)))
    assert v[fixed.vertices[up], 1] > v[fixed.vertices[low], 1]
    assert len(set(fixed.vertices.tolist())) == len(names)


def test_lip_line_cut_opens_the_mouth_and_sets_the_points():
    v, tris = grid(21)
    row = lambda y: [nearest(v, x, y) for x in np.linspace(-1.0, 1.0, 5)]  # noqa: E731
    upper, lower = row(-1.5), row(-2.0)
    upper[0] = lower[0] = nearest(v, -1.5, -1.75)
    upper[-1] = lower[-1] = nearest(v, 1.5, -1.75)
    cut = cut_lip_line(tris, upper, lower)
    removed = {tuple(sorted(t)) for t in tris.tolist()} - {tuple(sorted(t)) for t in cut.tolist()}
    assert removed and all(set(t) <= set(upper) | set(lower) for t in removed)
    names = ("lip_upper_inner", "lip_lower_inner", "mouth_inner_R", "mouth_inner_L", "nose_tip")
    guess = ControlPoints(names, np.array([lower[2], upper[2], row(-1.0)[0], row(-1.0)[4], nearest(v, 0, 0)]))
    fixed = fix_inner_lips(guess, v, cut, np.arange(len(v)), slit=(upper, lower))
    assert fixed.vertex("lip_upper_inner") == upper[2] and fixed.vertex("lip_lower_inner") == lower[2]
    assert fixed.vertex("mouth_inner_R") == upper[0] and fixed.vertex("mouth_inner_L") == upper[-1]
