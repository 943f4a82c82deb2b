"""Views of a character: the vertices its shapes move."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.character import Character, moving_vertices, sparse_deltas

from helpers.kpls_characters import bump_character


def moving_by_loops(character: Character, fraction: float) -> list[int]:
    """The obvious reference: every vertex of every shape, one at a time."""
    dense = character.dense_deltas()
    largest = max((float(np.linalg.norm(d)) for shape in dense for d in shape), default=0.0)
    return [v for v in range(character.n_vertices)
            if any(np.linalg.norm(shape[v]) > fraction * largest for shape in dense)]


def with_deltas(character: Character, dense: np.ndarray) -> Character:
    offsets, indices, positions = sparse_deltas(dense)
    return Character(**{**character.__dict__, "shape_names": tuple(f"s{i}" for i in range(len(dense))),
                        "delta_offsets": offsets, "delta_indices": indices, "delta_positions": positions,
                        "delta_normals": np.zeros_like(positions)})


@pytest.mark.parametrize("fraction", [0.0, 0.05, 0.5, 0.99])
def test_moving_vertices_match_the_loop_reference(fraction):
    character = bump_character()
    got = moving_vertices(character, fraction)
    assert got.dtype == np.int64 and np.all(np.diff(got) > 0)
    assert got.tolist() == moving_by_loops(character, fraction)


@pytest.mark.parametrize("n_shapes", [0, 2])
def test_a_character_nothing_moves_has_no_moving_vertices(n_shapes):
    character = bump_character()
    still = with_deltas(character, np.zeros((n_shapes, character.n_vertices, 3), np.float32))
    assert len(still.delta_indices) == 0
    got = moving_vertices(still)
    assert got.dtype == np.int64 and got.shape == (0,)


def test_stored_zero_deltas_move_nothing():
    character = bump_character()
    zero = Character(**{**character.__dict__, "shape_names": ("still",), "delta_offsets": np.array([0, 3], np.int64),
                        "delta_indices": np.arange(3, dtype=np.uint32), "delta_positions": np.zeros((3, 3), np.float32),
                        "delta_normals": np.zeros((3, 3), np.float32)})
    assert moving_vertices(zero, 0.0).shape == (0,) and moving_vertices(zero).shape == (0,)
