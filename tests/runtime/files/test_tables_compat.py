"""Tables files written before a change still load after it: one small file of each kind, kept as written.

The files in ``data/tables_v1/`` were written once by the save of commit 00238e2 (``make.py`` beside them
says how). Each must load through its class, hold exactly the arrays the archive holds, and, saved
again, give the same manifest and the same arrays: the file format has not moved.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.files.tables import load_tables, save_tables, schema_of
from facepuppet.runtime.gestures.tables import load_gesture_db
from facepuppet.runtime.kpls.stage import KplsRetarget
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.voice.table import VoiceTable

V1 = Path(__file__).parent / "data" / "tables_v1"
CLASSES = {"character": Character, "actor": Actor, "actor_pair": ActorPair, "elastic": ElasticModel,
           "retarget_kpls": KplsRetarget, "voice": VoiceTable}


def archive_arrays(path) -> dict[str, np.ndarray]:
    """The arrays of a tables file read straight from the archive, without the tables code."""
    with np.load(path, allow_pickle=False) as npz:
        return {name: npz[name] for name in npz.files if name != "__manifest__"}


def without_version(manifest) -> dict:
    # A v1 table saved again is written at its kind's current schema version (character and voice: 2, which
    # only added optional sections); everything else must be as it was, but for the sections' descriptions
    # where the version rose (voice 2 lists its new model code in model_params' description).
    out = {k: v for k, v in manifest.items() if k not in ("created_by", "schema_version")}
    if schema_of(manifest["kind"]).version > 1:
        out["sections"] = {name: {k: v for k, v in sec.items() if k != "kind"}
                           for name, sec in manifest["sections"].items()}
    return out


@pytest.mark.parametrize("kind", sorted(CLASSES))
def test_a_v1_table_loads_and_saves_back_unchanged(kind, tmp_path):
    path = V1 / f"{kind}.npz"
    old = load_tables(path, kind)
    assert old.manifest["schema_version"] == 1 and old.manifest["kind"] == kind
    raw = archive_arrays(path)
    assert sorted(raw) == sorted(old.arrays)
    for name, arr in raw.items():
        assert old[name].dtype == arr.dtype, name
        np.testing.assert_array_equal(old[name], arr, err_msg=name)
    table = CLASSES[kind].load(path)
    again = load_tables(table.save(tmp_path / f"{kind}.npz"), kind)
    assert without_version(again.manifest) == without_version(old.manifest)
    assert again.manifest["schema_version"] == schema_of(kind).version
    for name, arr in raw.items():
        assert again[name].dtype == arr.dtype, name
        np.testing.assert_array_equal(again[name], arr, err_msg=name)


def test_v1_tables_keep_their_values():
    character = Character.load(V1 / "character.npz")
    assert character.name == "quad" and character.units == "cm"
    assert character.shape_names == ("jawOpen", "eyeBlinkLeft")
    np.testing.assert_array_equal(character.dense_deltas()[0, 2], [0, 0.5, 0])
    actor = Actor.load(V1 / "actor.npz")
    assert actor.n_markers == 12 and actor.n_actuations == 4 and actor.linear is not None
    assert actor.metadata["settings"] == {"ridge": 0.03} and actor.metadata["metrics"] == {"rms": 0.08}
    np.testing.assert_array_equal(actor.s_lower, np.full(4, -0.5, np.float32))
    pair = ActorPair.load(V1 / "actor_pair.npz")
    assert pair.shape_names == ("jawOpen", "cheekPuff")
    np.testing.assert_array_equal(pair.similarity, np.eye(4, dtype=np.float32))
    elastic = ElasticModel.load(V1 / "elastic.npz")
    assert elastic.n_rigid == 1 and elastic.control_names == ("c0", "c1", "c2")
    stage = KplsRetarget.load(V1 / "retarget_kpls.npz")
    assert (stage.kernel, stage.gamma, stage.degree) == ("rbf", pytest.approx(0.05), 2)
    db = load_gesture_db(V1 / "gesture_db.npz")
    assert db.settings == {"fps": 30.0} and db["features"].shape == (40, 7)


def test_a_v1_gesture_db_saves_back_unchanged(tmp_path):
    old = load_gesture_db(V1 / "gesture_db.npz")
    path = save_tables(tmp_path / "g.npz", "gesture_db", dict(old.arrays), units=old.units,
                       channels=dict(old.channels), settings=dict(old.settings))
    assert without_version(load_tables(path).manifest) == without_version(old.manifest)
