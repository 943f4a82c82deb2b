"""Writes the tables files of this folder: one small table of each kind, by the save of commit 00238e2.

They were written once, before tables.py had its public schema API, and are kept as they came out:
tests/runtime/test_tables_compat.py loads them with today's code. Run from the repository root
(``python tests/runtime/files/data/tables_v1/make.py``) only to make a new folder for a new schema version.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[3]))  # tests/, for the helpers

from runtime.test_tables import tiny_character  # noqa: E402

from facepuppet.runtime.actuation.pair import ActorPair  # noqa: E402
from facepuppet.runtime.elastic.model import ElasticModel, no_muscles  # noqa: E402

from helpers.gesture_dbs import small_db  # noqa: E402
from helpers.kpls_stages import random_stage  # noqa: E402
from helpers.small_actors import K, N, make_actor  # noqa: E402


def main() -> None:
    character = tiny_character()
    character.save(HERE / "character.npz")
    actor = make_actor()
    rng = np.random.default_rng(3)
    actor = type(actor)(**{**actor.__dict__, "linear": rng.normal(size=(K, N, 3)),
                           "metadata": {"settings": {"ridge": 0.03}, "metrics": {"rms": 0.08}}})
    actor.save(HERE / "actor.npz")
    ActorPair(cubic=rng.normal(size=(3, K, 2)), shape_names=("jawOpen", "cheekPuff"), marker_names=actor.names,
              marker_vertices=np.arange(N) % 4, similarity=np.eye(4), s_lower=actor.s_lower, s_upper=actor.s_upper,
              metadata={"settings": {"levels": 12}}).save(HERE / "actor_pair.npz")
    n, k, c = character.n_vertices, 2, 3
    arrays = {
        "basis_indices": rng.integers(0, c, (n, k)).astype(np.uint16),
        "basis_weights": rng.uniform(0, 0.5, (n, k)).astype(np.float32),
        "basis_gradients": (0.2 * rng.standard_normal((n, k, 3))).astype(np.float32),
        "control_vertices": np.arange(c, dtype=np.int64),
        "control_positions": character.vertices[:c].copy(),
        "params": (0.1 * rng.standard_normal((character.n_shapes, c, 3))).astype(np.float32),
        **no_muscles(c),
        "rigid_labels": np.array([-1, 0, 0, -1], np.int32),
        "rigid_anchors": np.ones((1, c), np.uint8),
    }
    ElasticModel(arrays, character.shape_names, ("c0", "c1", "c2")).save(HERE / "elastic.npz")
    random_stage(n_train=8, n_features=4).save(HERE / "retarget_kpls.npz")
    # the voice kind came later: its file was written by the voice table's first code, the same way
    from helpers.voice_tables import small_table

    small_table("kpls").save(HERE / "voice.npz")
    small_db(HERE / "gesture_db.npz", n=20)


if __name__ == "__main__":
    main()
