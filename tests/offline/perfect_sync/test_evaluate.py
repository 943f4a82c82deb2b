"""The artist-shape comparison: cosine and magnitude ratio, with a cloned side that is a sum of shapes."""

import numpy as np
import pytest

from facepuppet.offline.elastic.clone import character_with_shapes, mesh_character
from facepuppet.offline.perfect_sync.evaluate import GODETTE_PAIRS, pair_similarity


def _character():
    rng = np.random.default_rng(5)
    v = rng.normal(size=(40, 3)).astype(np.float32)
    t = np.array([[i, i + 1, i + 2] for i in range(38)], np.uint32)
    left, right = np.zeros((40, 3)), np.zeros((40, 3))
    left[:20, 1], right[20:, 1] = 0.5, 0.5  # one eye each
    both = left + right
    return character_with_shapes(mesh_character(v, t, "two eyes"), {"lookL": left, "lookR": right, "look": both})


def test_one_eye_against_a_both_eyes_shape_and_their_sum():
    c = _character()
    every = np.arange(40)
    one = pair_similarity(c, "lookL", "look", every)
    assert one["cosine"] == pytest.approx(1 / np.sqrt(2), abs=1e-6)  # half the artist's motion: at most 0.71
    assert one["magnitude_ratio"] == pytest.approx(1 / np.sqrt(2), abs=1e-6)
    both = pair_similarity(c, "lookL+lookR", "look", every)
    assert both["cosine"] == pytest.approx(1.0, abs=1e-6) and both["magnitude_ratio"] == pytest.approx(1.0, abs=1e-6)


def test_godette_looks_are_compared_with_both_eyes():
    sums = {artist: key for key, artist in GODETTE_PAIRS if "+" in key}
    assert sums == {"look_up": "eyeLookUpLeft+eyeLookUpRight", "look_down": "eyeLookDownLeft+eyeLookDownRight",
                    "look_left": "eyeLookOutLeft+eyeLookInRight", "look_right": "eyeLookInLeft+eyeLookOutRight"}
