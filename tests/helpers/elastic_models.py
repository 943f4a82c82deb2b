"""A random elastic model over a small character, for the elastic tests."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.elastic.model import ElasticModel, no_muscles


def random_model(character, n_controls=6, k=4, seed=0) -> ElasticModel:
    rng = np.random.default_rng(seed)
    n = character.n_vertices
    arrays = {
        "basis_indices": rng.integers(0, n_controls, (n, k)).astype(np.uint16),
        "basis_weights": rng.uniform(0, 0.5, (n, k)).astype(np.float32),
        "basis_gradients": (0.2 * rng.standard_normal((n, k, 3))).astype(np.float32),
        "control_vertices": np.arange(n_controls, dtype=np.int64),
        "control_positions": character.vertices[:n_controls].copy(),
        "params": (0.1 * rng.standard_normal((character.n_shapes, n_controls, 3))).astype(np.float32),
        **no_muscles(n_controls),
    }
    return ElasticModel(arrays, tuple(character.shape_names), tuple(f"c{i}" for i in range(n_controls)))
