"""The ``gesture_db`` tables contract: its schema, its loader, and the names of its feature groups.

The reference database of Ju & Lee (2008) gestures, written offline by
``facepuppet build-gestures`` (:mod:`facepuppet.offline.gestures.database`) and read at
runtime by :class:`~facepuppet.runtime.gestures.synth.GestureSynth`. Per frame at
the animation rate it holds the normalised speech intensity s(t) (a z-score
floored at :data:`~facepuppet.runtime.gestures.speaker_normaliser.SILENCE_Z`), the
features of the groups :data:`GROUPS` (lips P(t), mood c(t), the residuals
D_j(t) of brows, eyes and rest, the head pose named :data:`HEAD_FEATURES`), the
take of the frame and which groups that take provides.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from facepuppet.runtime.files.tables import Section, TableSchema, TablesError, load_tables, register_schema

if TYPE_CHECKING:
    import os

    from facepuppet.runtime.files.tables import Tables

GROUPS = ("lips", "mood", "brows", "eyes", "rest", "head")
LEVEL1 = ("lips", "mood")
HEAD_FEATURES = ("headYaw", "headPitch", "headRoll", "headX", "headY", "headZ")

GESTURE_DB_SCHEMA = register_schema(TableSchema(
    kind="gesture_db",
    sections={
        "intensity": Section("float32", ("n_frames",), "speech intensity s(t), per-speaker z-score of dB"),
        "features": Section("float32", ("n_frames", "n_features"), "P(t), c(t), D_j(t), head per frame"),
        "feature_group": Section("int32", ("n_features",), "group id of each feature (index into GROUPS)"),
        "feature_scale": Section("float32", ("n_features",), "per-feature std, for the distances"),
        "blend_basis": Section("float32", ("n_basis", "n_features"), "whole-face expressions B (§4.1)"),
        "frame_take": Section("int32", ("n_frames",), "take index of each frame"),
        "available": Section("bool", ("n_frames", 6), "whether the frame's take provides each group"),
        "detail_weights": Section("float32", ("n_frames", "n_detail"), "§5.2 detail shape weights per frame "
                                  "(marker-take frames; zero elsewhere), shapes named by channels.detail",
                                  optional=True),
    },
    channels=("features", "takes", "groups"),
    channel_dims={"features": "n_features", "detail": "n_detail"},
))


def load_gesture_db(path: str | os.PathLike) -> Tables:
    """Load and check a ``gesture_db`` tables file; TablesError naming the field otherwise."""
    db = load_tables(path, kind="gesture_db")
    if list(db.channels["groups"]) != list(GROUPS):
        raise TablesError(path, "channels.groups", f"expected {list(GROUPS)}, found {db.channels['groups']}")
    n_takes = len(db.channels["takes"])
    take = db["frame_take"]
    if take.size and (take.min() < 0 or take.max() >= n_takes):
        raise TablesError(path, "frame_take", f"expected take indices in [0, {n_takes}), found "
                                              f"{take.min()}..{take.max()}")
    groups = db["feature_group"]
    if groups.size and (groups.min() < 0 or groups.max() >= len(GROUPS)):
        raise TablesError(path, "feature_group", f"expected group ids in [0, {len(GROUPS)})")
    fps = db.settings.get("fps", 30.0)
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (math.isfinite(fps) and fps > 0):
        raise TablesError(path, "settings.fps", f"expected a positive number of frames per second, found {fps!r}")
    return db
