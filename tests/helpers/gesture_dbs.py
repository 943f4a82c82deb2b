"""A small synthetic gesture_db (helper and module-scoped fixture ``db``) shared by the gesture synthesis and
gesture table tests; a test file uses the fixture by importing it."""

import numpy as np
import pytest

from facepuppet.runtime.files.tables import save_tables
from facepuppet.runtime.gestures.tables import GROUPS, load_gesture_db


def small_db(path, n_takes=2, n=300, seed=0):
    """A synthetic gesture_db: lips follow the intensity (jawOpen = loudness), random-walk gestures."""
    rng = np.random.default_rng(seed)
    names = ["jawOpen", "mood_0", "mood_1", "browInnerUp", "eyeBlinkLeft", "cheekPuff", "headYaw"]
    group = [GROUPS.index(g) for g in ("lips", "mood", "mood", "brows", "eyes", "rest", "head")]
    N = n_takes * n
    t = np.arange(N)
    intensity = np.where(np.sin(t / 13.0) > 0, np.sin(t / 5.0) + rng.normal(0, 0.1, N), -3.0)
    F = np.zeros((N, len(names)))
    F[:, 0] = np.clip((intensity + 3.0) / 4.0, 0, 1)
    F[:, 1:] = np.cumsum(rng.normal(0, 0.05, (N, len(names) - 1)), 0)
    basis = np.zeros((2, len(names)))
    basis[0, 3], basis[1, 4] = 0.3, 0.2
    arrays = {
        "intensity": intensity.astype(np.float32), "features": F.astype(np.float32),
        "feature_group": np.array(group, np.int32), "feature_scale": F.std(0).astype(np.float32),
        "blend_basis": basis.astype(np.float32), "frame_take": np.repeat(np.arange(n_takes), n).astype(np.int32),
        "available": np.ones((N, 6), bool),
    }
    save_tables(path, "gesture_db", arrays, channels={"features": names, "takes": [f"take{i}" for i in range(n_takes)],
                                                      "groups": list(GROUPS)}, settings={"fps": 30.0})
    return load_gesture_db(path)


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    return small_db(tmp_path_factory.mktemp("g") / "g.npz")
