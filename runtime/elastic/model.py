"""The elastic character tables (Yano & Harada 2009) and their CPU evaluation.

An ``elastic`` tables file goes with a character of the same vertex count. It
holds the compact basis (k control points per vertex, their weights and the
surface gradients of their basis functions), the expression parameters of
every shape (eq. 6, fitted offline) and the muscles (§6) as control
displacements per unit contraction. Per frame:

    U = Σ_s w_s P_s + Σ_m c_m Q_m          (eq. 7 blending; muscles, §6)
    x_v = x0_v + Σ_j b_vj u_{i_vj}        (eq. 5, k terms)
    n_v ≈ n0_v - Σ_j g_vj (n0_v · u_{i_vj})  (first-order normal change)
    x_v = R_p x0_v + t_p, n_v = R_p n0_v      (vertex of rigid part p, e.g. the lower teeth)

Rigid parts (optional sections): handle-free pieces that follow a rigid
transform (R_p, t_p) fitted per frame (Kabsch) to the displaced anchor
controls of part p, e.g. the lower teeth and tongue to the chin and jaw.

Symbols → code names: P_s ``params[s]``, Q_m ``muscle_params[m]``,
w ``weights``, c ``contractions``, b ``basis_weights``, i ``basis_indices``,
g ``basis_gradients``, U ``controls``.
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
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)
from facepuppet.runtime.model.rigid import kabsch

MUSCLE_KINDS = {"linear": 0, "sphincter": 1}

ELASTIC_SCHEMA = register_schema(
    TableSchema(
        kind="elastic",
        sections={
            "basis_indices": Section("uint16", ("n_vertices", "k"), "control index per kept weight"),
            "basis_weights": Section("float32", ("n_vertices", "k"), "basis function value b_i(x_v)"),
            "basis_gradients": Section("float32", ("n_vertices", "k", 3), "surface gradient of b_i at x_v"),
            "control_vertices": Section("int64", ("n_controls",), "vertex index of each control point"),
            "control_positions": Section("float32", ("n_controls", 3), "neutral control-point positions"),
            "params": Section("float32", ("n_shapes", "n_controls", 3), "expression parameters, eq. 6"),
            "muscle_params": Section("float32", ("n_muscles", "n_controls", 3),
                                     "control displacement per unit contraction"),
            "muscle_kinds": Section("uint8", ("n_muscles",), "0 linear, 1 sphincter"),
            "muscle_points": Section("float32", ("n_muscles", 2, 3),
                                     "linear: attachment, insertion; sphincter: centre, (lx, ly, 0)"),
            "muscle_ranges": Section("float32", ("n_muscles", 4),
                                     "linear: Rs, Rf, Ω (rad), strength; sphincter: lx, ly, strength, 0"),
            "rigid_labels": Section("int32", ("n_vertices",), "rigid part of each vertex, -1 for none", optional=True),
            "rigid_anchors": Section("uint8", ("n_rigid", "n_controls"), "controls each part's transform is fitted to",
                                     optional=True),
        },
        channels=("shapes", "controls", "muscles"),
        channel_dims={"shapes": "n_shapes", "controls": "n_controls", "muscles": "n_muscles"},
    )
)


@dataclass(frozen=True, eq=False)
class ElasticModel:
    """A loaded, validated elastic table (see the module docstring for the symbols).

    Attributes
    ----------
    arrays : dict of the schema's sections
    shape_names, control_names, muscle_names : tuple of str
    units : str
    metadata : dict with settings and metrics
    """

    arrays: Mapping[str, np.ndarray]
    shape_names: tuple
    control_names: tuple
    muscle_names: tuple = ()
    units: str = "cm"
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        dims = validate(ELASTIC_SCHEMA, self.arrays, self._channels())
        if dims["n_controls"] and int(self.arrays["basis_indices"].max(initial=0)) >= dims["n_controls"]:
            raise TablesError(None, "basis_indices", f"control index out of range for {dims['n_controls']} controls")
        if ("rigid_labels" in self.arrays) != ("rigid_anchors" in self.arrays):
            raise TablesError(None, "rigid_labels", "rigid_labels and rigid_anchors come together")
        if "rigid_labels" in self.arrays:
            labels, anchors = self.arrays["rigid_labels"], self.arrays["rigid_anchors"]
            if len(labels) and not (-1 <= labels.min() and labels.max() < len(anchors)):
                raise TablesError(None, "rigid_labels", f"part index out of range -1..{len(anchors) - 1}")
            if len(anchors) and (anchors.sum(axis=1) < 3).any():
                raise TablesError(None, "rigid_anchors", "each rigid part needs at least 3 anchor controls")

    def _channels(self) -> dict:
        return {"shapes": list(self.shape_names), "controls": list(self.control_names),
                "muscles": list(self.muscle_names)}

    # -- sizes -------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return self.arrays["basis_weights"].shape[0]

    @property
    def k(self) -> int:
        return self.arrays["basis_weights"].shape[1]

    @property
    def n_controls(self) -> int:
        return len(self.control_names)

    @property
    def n_rigid(self) -> int:
        return len(self.arrays["rigid_anchors"]) if "rigid_anchors" in self.arrays else 0

    @property
    def channel_names(self) -> tuple:
        """Input channels: the shapes, then the muscles (``--input`` names)."""
        return tuple(self.shape_names) + tuple(self.muscle_names)

    # -- per frame ---------------------------------------------------------
    def blend(self, weights: np.ndarray) -> np.ndarray:
        """Control displacements of blended expressions, U = Σ_s w_s P_s (eq. 7), (n_c, 3) float32."""
        w = np.asarray(weights, np.float32)
        if w.shape != (len(self.shape_names),):
            raise ValueError(f"weights: expected shape ({len(self.shape_names)},) in elastic shape order, "
                             f"got {w.shape}")
        return np.tensordot(w, self.arrays["params"], axes=1)  # Yano & Harada eq. 7

    def contract(self, contractions: np.ndarray) -> np.ndarray:
        """Control displacements of muscle contractions, Σ_m c_m Q_m (§6), (n_c, 3) float32."""
        c = np.asarray(contractions, np.float32)
        if c.shape != (len(self.muscle_names),):
            raise ValueError(f"contractions: expected shape ({len(self.muscle_names)},) in muscle order, got {c.shape}")
        return np.tensordot(c, self.arrays["muscle_params"], axes=1)

    def controls(self, values: np.ndarray) -> np.ndarray:
        """Control displacements from one vector of all channels (shapes then muscles), (n_c, 3) float32."""
        v = np.asarray(values, np.float32)
        n_s = len(self.shape_names)
        if v.shape != (len(self.channel_names),):
            raise ValueError(f"values: expected shape ({len(self.channel_names)},) (shapes then muscles), "
                             f"got {v.shape}")
        return self.blend(v[:n_s]) + self.contract(v[n_s:])

    def rigid_transforms(self, controls: np.ndarray) -> np.ndarray:
        """Per rigid part, [R | t] fitted (Kabsch) to its displaced anchor controls, (n_rigid, 3, 4) float32."""
        u = np.asarray(controls, np.float32)
        out = np.zeros((self.n_rigid, 3, 4), np.float32)
        rest = self.arrays["control_positions"]
        for p, anchors in enumerate(self.arrays.get("rigid_anchors", ())):
            a = anchors.astype(bool)
            r, t = kabsch(rest[a] + u[a], rest[a])  # x' = R x + t moves the rest anchors onto the displaced ones
            out[p, :, :3], out[p, :, 3] = r, t
        return out

    def deform(self, controls: np.ndarray, rest_positions: np.ndarray,
               rest_normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """CPU reference of the vertex shader: positions and unit normals, (n, 3) float32 each."""
        u = np.asarray(controls, np.float32)
        if u.shape != (self.n_controls, 3):
            raise ValueError(f"controls: expected shape ({self.n_controls}, 3), got {u.shape}")
        a = self.arrays
        picked = u[a["basis_indices"].astype(np.int64)]  # (n, k, 3)
        n0 = np.asarray(rest_normals, np.float32)
        n0 = n0 / np.maximum(np.linalg.norm(n0, axis=1, keepdims=True), 1e-12)
        positions = (np.asarray(rest_positions, np.float32)
                     + np.einsum("vk,vkc->vc", a["basis_weights"], picked))  # eq. 5
        along = np.einsum("vc,vkc->vk", n0, picked)
        normals = n0 - np.einsum("vk,vkc->vc", along, a["basis_gradients"])
        if self.n_rigid:
            labels = a["rigid_labels"]
            x0 = np.asarray(rest_positions, np.float32)
            for p, m in enumerate(self.rigid_transforms(u)):
                on = labels == p
                positions[on] = x0[on] @ m[:, :3].T + m[:, 3]
                normals[on] = n0[on] @ m[:, :3].T
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        return positions.astype(np.float32), normals.astype(np.float32)

    # -- tables ------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        return save_tables(path, "elastic", dict(self.arrays), units=self.units, channels=self._channels(),
                           metadata=self.metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> ElasticModel:
        t = load_tables(path, kind="elastic")
        with naming_file(path):
            return cls(
                arrays=dict(t.arrays),
                shape_names=tuple(t.channels["shapes"]),
                control_names=tuple(t.channels["controls"]),
                muscle_names=tuple(t.channels["muscles"]),
                units=t.units,
                metadata=t.metadata,
            )


def no_muscles(n_controls: int) -> dict:
    """The muscle sections for a table without muscles."""
    return {
        "muscle_params": np.zeros((0, n_controls, 3), np.float32),
        "muscle_kinds": np.zeros(0, np.uint8),
        "muscle_points": np.zeros((0, 2, 3), np.float32),
        "muscle_ranges": np.zeros((0, 4), np.float32),
    }
