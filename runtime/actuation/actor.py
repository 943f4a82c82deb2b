"""The actor table: an actor's cubic deformation model (Shin & Lee 2009, §5 eq 2).

Paper symbols -> code names:

    s                actuation parameters                 s           (K,)
    x_i^0            marker i at s = 0                    actor.neutral        (n_markers, 3)
    x_i(s)           marker i in head coordinates         evaluate(s) (n_markers, 3)
    a, b, c          cubic coefficients                   actor.cubic[0|1|2]   (3, K, n_markers, 3)

Eq 2: x_i(s) = x_i^0 + sum_k a_ik s_k^3 + b_ik s_k^2 + c_ik s_k.
The per-frame solve of s from markers (eq 5) is :mod:`facepuppet.runtime.actuation.solver`; the
transfer table s -> character weights (§6.2) is :mod:`facepuppet.runtime.actuation.pair`.
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
    TablesError,
    coerce,
    hash_inputs,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)

ACTOR_SCHEMA = register_schema(TableSchema(
    kind="actor",
    sections={
        "neutral": Section("float32", ("n_markers", 3), "marker positions at s = 0, head coordinates"),
        "cubic": Section("float32", (3, "n_actuations", "n_markers", 3), "a, b, c of eq 2"),
        "linear": Section("float32", ("n_actuations", "n_markers", 3), "linear ICA model (comparison)", True),
        "unmixing": Section("float32", ("n_actuations", "n_classes"), "ICA unmixing, normalised"),
        "class_axes": Section("float32", ("n_classes", 3), "class axes on the unit sphere"),
        "class_marker": Section("int32", ("n_classes",), "marker of each class"),
        "head_markers": Section("int32", ("n_head",), "rigid head marker indices"),
        "s_lower": Section("float32", ("n_actuations",), "solver lower bounds"),
        "s_upper": Section("float32", ("n_actuations",), "solver upper bounds"),
        "s_samples": Section("float32", ("n_samples", "n_actuations"), "s of frames of the training take", True),
    },
    channels=("markers", "actuations"),
    channel_dims={"markers": "n_markers", "actuations": "n_actuations"},
))


@dataclass(frozen=True, eq=False)
class Actor:
    """An actor's deformation model, validated against the ``actor`` schema when built.

    Attributes
    ----------
    names : tuple of n_markers str
    units : str, the capture's units
    neutral : ndarray of shape (n_markers, 3), float32, units, head coordinates
    cubic : ndarray of shape (3, K, n_markers, 3), float32, units ([a, b, c] of eq 2)
    unmixing : ndarray of shape (K, n_classes), float32
    class_axes : ndarray of shape (n_classes, 3), float32
    class_marker : ndarray of shape (n_classes,), int32
    head_markers : ndarray of shape (n_head,), int32
    s_lower, s_upper : ndarray of shape (K,), float32
    linear : ndarray of shape (K, n_markers, 3), float32, or None
    s_samples : ndarray of shape (n_samples, K), float32, or None: the actuations of frames of the training
        take, evenly spaced. They are the poses the solve really lands in, nearly collinear actuations
        cancelling each other near rest included, so the transfer fits the pair table on them
    metadata : dict with "settings", "metrics", "input_hash"
    """

    names: tuple[str, ...]
    units: str
    neutral: np.ndarray
    cubic: np.ndarray
    unmixing: np.ndarray
    class_axes: np.ndarray
    class_marker: np.ndarray
    head_markers: np.ndarray
    s_lower: np.ndarray
    s_upper: np.ndarray
    linear: np.ndarray | None = None
    s_samples: np.ndarray | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, arr in coerce(ACTOR_SCHEMA, self._arrays()).items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "names", tuple(self.names))
        validate(ACTOR_SCHEMA, self._arrays(), self._channels())
        if np.any(self.s_lower > 0) or np.any(self.s_upper < 0):
            raise TablesError(None, "s_lower/s_upper", "bounds must contain s = 0 (the neutral)")

    @property
    def n_markers(self) -> int:
        return len(self.names)

    @property
    def n_actuations(self) -> int:
        return self.cubic.shape[1]

    def _arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in ACTOR_SCHEMA.sections if getattr(self, name) is not None}

    def _channels(self) -> dict[str, list[str]]:
        return {"markers": list(self.names), "actuations": [f"s{k + 1:02d}" for k in range(self.n_actuations)]}

    def save(self, path: str | os.PathLike) -> Path:
        return save_tables(path, "actor", self._arrays(), units=self.units, channels=self._channels(),
                           metadata=self.metadata,
                           input_hash=self.metadata.get("input_hash", "") or hash_inputs(self.cubic))

    @classmethod
    def load(cls, path: str | os.PathLike) -> Actor:
        t = load_tables(path, "actor")
        with naming_file(path):
            return cls(names=tuple(t.channels["markers"]), units=t.units,
                       **{name: np.array(t[name]) for name in ACTOR_SCHEMA.sections if name in t.arrays},
                       metadata=t.metadata)

    def evaluate(self, s: np.ndarray) -> np.ndarray:
        """Markers x(s) (eq 2): ndarray of shape (n_markers, 3), float64, units, head coordinates."""
        s = np.asarray(s, dtype=np.float64)
        if s.shape != (self.n_actuations,):
            raise ValueError(f"Actor.evaluate: s must have shape ({self.n_actuations},), got {s.shape}")
        c = self.cubic.reshape(3, self.n_actuations, -1).astype(np.float64)
        x = (s ** 3) @ c[0] + (s ** 2) @ c[1] + s @ c[2]           # Shin & Lee eq. 2
        return self.neutral + x.reshape(-1, 3)
