"""The gesture_db table loader: validation of the stored arrays."""

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError, save_tables
from facepuppet.runtime.gestures.tables import load_gesture_db


def test_loading_refuses_a_table_with_bad_take_indices(tmp_path, db):
    arrays = {k: np.array(v) for k, v in db.arrays.items()}
    arrays["frame_take"][0] = 7
    save_tables(tmp_path / "bad.npz", "gesture_db", arrays, channels=dict(db.channels))
    with pytest.raises(TablesError, match="frame_take"):
        load_gesture_db(tmp_path / "bad.npz")


@pytest.mark.parametrize("fps", [-1.0, 0, "30", True, None, [30]])
def test_loading_refuses_a_table_whose_frame_rate_is_not_a_positive_number(tmp_path, db, fps):
    arrays = {k: np.array(v) for k, v in db.arrays.items()}
    save_tables(tmp_path / "bad.npz", "gesture_db", arrays, channels=dict(db.channels), settings={"fps": fps})
    with pytest.raises(TablesError, match=r"bad\.npz: settings\.fps: expected a positive number"):
        load_gesture_db(tmp_path / "bad.npz")
