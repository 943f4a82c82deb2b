"""The actor pair table: actuations s -> a character's blendshape weights (Shin & Lee 2009, §6.2).

Paper symbols -> code names:

    s                actuation parameters                 s              (K,)
    a, b, c          cubic coefficients of the weights    pair.cubic[0|1|2]  (3, K, n_shapes)
    w(s)             character blendshape weights         weights(s)     (n_shapes,)

The cubic of eq 2, fitted on the character's weights instead of markers:
w(s) = sum_k a_k s_k^3 + b_k s_k^2 + c_k s_k, clipped to [0, 1].
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.files.tables import (
    Section,
    TableSchema,
    coerce,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)

PAIR_SCHEMA = register_schema(TableSchema(
    kind="actor_pair",
    sections={
        "cubic": Section("float32", (3, "n_actuations", "n_shapes"), "a, b, c: s -> character weights"),
        "marker_vertices": Section("int32", ("n_markers",), "character vertex of each actor marker"),
        "similarity": Section("float32", (4, 4), "actor head coords -> character coords"),
        "s_lower": Section("float32", ("n_actuations",), "fitted range of s (weights() clamps to it)"),
        "s_upper": Section("float32", ("n_actuations",), "fitted range of s (weights() clamps to it)"),
    },
    channels=("markers", "actuations", "shapes"),
    channel_dims={"markers": "n_markers", "actuations": "n_actuations", "shapes": "n_shapes"},
))


@dataclass(frozen=True, eq=False)
class ActorPair:
    """Actuations -> a character's blendshape weights (Shin & Lee §6.2), from an ``actor_pair`` table.

    Attributes
    ----------
    cubic : ndarray of shape (3, K, n_shapes), float32
    shape_names : tuple of n_shapes str
    marker_names : tuple of n_markers str
    marker_vertices : ndarray of shape (n_markers,), int32
    similarity : ndarray of shape (4, 4), float32, actor head coordinates -> character coordinates
    s_lower, s_upper : ndarray of shape (K,), float32
    metadata : dict
    """

    cubic: np.ndarray
    shape_names: tuple[str, ...]
    marker_names: tuple[str, ...]
    marker_vertices: np.ndarray
    similarity: np.ndarray
    s_lower: np.ndarray
    s_upper: np.ndarray
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, arr in coerce(PAIR_SCHEMA, self._arrays()).items():
            object.__setattr__(self, name, arr)
        validate(PAIR_SCHEMA, self._arrays(), self._channels())
        object.__setattr__(self, "_flat", self.cubic.astype(np.float64).reshape(-1, self.cubic.shape[2]))

    def _arrays(self):
        return {name: getattr(self, name) for name in PAIR_SCHEMA.sections}

    def _channels(self):
        k = self.cubic.shape[1]
        return {"markers": list(self.marker_names), "actuations": [f"s{i + 1:02d}" for i in range(k)],
                "shapes": list(self.shape_names)}

    def save(self, path: str | os.PathLike) -> Path:
        return save_tables(path, "actor_pair", self._arrays(), channels=self._channels(), metadata=self.metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> ActorPair:
        t = load_tables(path, "actor_pair")
        with naming_file(path):
            return cls(shape_names=tuple(t.channels["shapes"]), marker_names=tuple(t.channels["markers"]),
                       **{name: np.array(t[name]) for name in PAIR_SCHEMA.sections}, metadata=t.metadata)

    def weights(self, s: np.ndarray) -> np.ndarray:
        """Character weights w(s) (n_shapes,), float32, clipped to [0, 1] (cubic of eq 2 on weights).

        s is first clamped to [s_lower, s_upper]: the range the tables were fitted over, so a solve
        that runs past it holds the last fitted pose instead of extrapolating the cubic.
        """
        s = np.clip(np.asarray(s, dtype=np.float64), self.s_lower, self.s_upper)
        w = np.concatenate([s ** 3, s ** 2, s]) @ self._flat        # Shin & Lee eq. 2, §6.2 target
        return np.clip(w, 0.0, 1.0).astype(np.float32)
