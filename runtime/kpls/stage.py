"""Kernel-PLS retarget stage: source channel weights -> target character weights, per frame.

The offline fitter (:mod:`facepuppet.offline.kpls.model`, Ouzounis, Kiliadis &
Mousas) writes a ``retarget_kpls`` tables file; this module loads it with
nothing but NumPy and evaluates eq. 10 for one frame:

    x   = F w_src                               source feature displacements
    k_i = k(x, X_i)                             one kernel row, i = 1..n
    ŷ   = (k − k̄ − mean(k) + k̿) B + ȳ          centred row (eq. 8) times the dual coefficients (eq. 10)

Symbols and names: F ``source_features``; X ``train_inputs``; B (the paper's
U (TᵀKU)⁻¹TᵀY) ``dual_coef``; k̄ ``kernel_col_mean``; k̿
``kernel_grand_mean``; ȳ ``target_mean``. The centring is folded into two
constant vectors when loaded, so a frame costs one (n, n_source) matrix-vector
product, one exp (rbf), one (n,) @ (n, m) product and a few vector ops; the feature
matrix F is folded into the training inputs (X F) when loaded, so weights go in directly.
With the linear kernel the whole of eq. 10 is linear in the weights and folds into one
(n_target, n_channels) matrix per channel tuple.

The stage implements the frame loop's ``Retarget`` protocol: ``target_names``
(the target character's shapes in order) and ``apply(frame) -> weights``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.files.tables import (
    Section,
    TableSchema,
    TablesError,
    coerce,
    load_tables,
    naming_file,
    register_schema,
    save_tables,
    validate,
)
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.mapping.channels import ChannelMap

if TYPE_CHECKING:
    from pathlib import Path

KERNEL_CODES = {"linear": 0, "rbf": 1, "poly": 2}

RETARGET_KPLS_SCHEMA = register_schema(
    TableSchema(
        kind="retarget_kpls",
        sections={
            "source_features": Section("float32", ("n_features", "n_source"),
                                       "feature displacements per source weight, units"),
            "train_inputs": Section("float32", ("n_train", "n_features"), "training inputs X"),
            "dual_coef": Section("float32", ("n_train", "n_target"), "U (T^T K U)^-1 T^T Y, eq. 10"),
            "kernel_col_mean": Section("float32", ("n_train",), "column means of the training Gram matrix"),
            "kernel_grand_mean": Section("float32", (1,), "grand mean of the training Gram matrix"),
            "target_mean": Section("float32", ("n_target",), "mean of the training outputs"),
            "kernel_params": Section("float32", (4,), "kernel code (0 linear, 1 rbf, 2 poly), gamma, coef0, degree"),
        },
        channels=("source", "target"),
        channel_dims={"source": "n_source", "target": "n_target"},
    )
)


@dataclass(frozen=True, eq=False)
class KplsRetarget:
    """A fitted kernel-PLS retarget, validated when built.

    Attributes
    ----------
    source_names : tuple of n_source str, the source character's shapes
    target_names : tuple of n_target str, the target character's shapes
    source_features : ndarray of shape (n_features, n_source), float32, units per weight
    train_inputs : ndarray of shape (n_train, n_features), float32
    dual_coef : ndarray of shape (n_train, n_target), float32
    kernel_col_mean : ndarray of shape (n_train,), float32
    kernel_grand_mean : float
    target_mean : ndarray of shape (n_target,), float32
    kernel : str, "linear", "rbf" or "poly"
    gamma, coef0 : float; degree : int
    units : str, units of the feature displacements
    metadata : dict, settings/metrics/input hash carried into the manifest
    """

    source_names: tuple[str, ...]
    target_names: tuple[str, ...]
    source_features: np.ndarray
    train_inputs: np.ndarray
    dual_coef: np.ndarray
    kernel_col_mean: np.ndarray
    kernel_grand_mean: float
    target_mean: np.ndarray
    kernel: str = "rbf"
    gamma: float = 1.0
    coef0: float = 1.0
    degree: int = 2
    units: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.kernel not in KERNEL_CODES:
            raise TablesError(None, "kernel_params",
                              f"kernel must be one of {tuple(KERNEL_CODES)}, got {self.kernel!r}")
        given = ("source_features", "train_inputs", "dual_coef", "kernel_col_mean", "target_mean")
        for name, arr in coerce(RETARGET_KPLS_SCHEMA, {name: getattr(self, name) for name in given}).items():
            set_(self, name, arr)
        set_(self, "source_names", tuple(self.source_names))
        set_(self, "target_names", tuple(self.target_names))
        validate(RETARGET_KPLS_SCHEMA, self._arrays(), self._channels())
        # Fold the centring (eq. 8) into constants: ŷ = k B − mean(k) s + c
        B = self.dual_coef.astype(np.float64)
        s = B.sum(axis=0)
        c = -self.kernel_col_mean.astype(np.float64) @ B + self.kernel_grand_mean * s + self.target_mean
        set_(self, "_coef_sum", s.astype(np.float32))
        set_(self, "_offset", c.astype(np.float32))
        set_(self, "_train_sq", (self.train_inputs.astype(np.float64) ** 2).sum(1).astype(np.float32))
        set_(self, "_code", KERNEL_CODES[self.kernel])
        # x = F w folded into the training side: X x = (X F) w and ‖x‖² = wᵀ (FᵀF) w
        F64 = self.source_features.astype(np.float64)
        set_(self, "_train_by_source", (self.train_inputs.astype(np.float64) @ F64).astype(np.float32))
        set_(self, "_source_gram", (F64.T @ F64).astype(np.float32))
        set_(self, "_maps", {})

    # -- tables ------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        return {
            "source_features": self.source_features, "train_inputs": self.train_inputs,
            "dual_coef": self.dual_coef, "kernel_col_mean": self.kernel_col_mean,
            "kernel_grand_mean": np.array([self.kernel_grand_mean], np.float32),
            "target_mean": self.target_mean,
            "kernel_params": np.array([KERNEL_CODES[self.kernel], self.gamma, self.coef0, self.degree], np.float32),
        }

    def _channels(self) -> dict[str, list[str]]:
        return {"source": list(self.source_names), "target": list(self.target_names)}

    def save(self, path: str | os.PathLike) -> Path:
        """Write a ``retarget_kpls`` tables file; returns its path."""
        settings = dict(self.metadata.get("settings", {}))
        settings["kernel"] = self.kernel
        return save_tables(path, "retarget_kpls", self._arrays(), units=self.units, channels=self._channels(),
                           settings=settings, metadata=self.metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> KplsRetarget:
        """Load and validate a ``retarget_kpls`` tables file (TablesError naming the file and field)."""
        t = load_tables(path, kind="retarget_kpls")
        a = t.arrays
        code, gamma, coef0, degree = (float(v) for v in a["kernel_params"])
        kernels = {v: k for k, v in KERNEL_CODES.items()}
        if code not in kernels:
            raise TablesError(path, "kernel_params", f"kernel code must be 0, 1 or 2, found {code:g}")
        if kernels[code] == "poly" and (degree < 1 or degree != int(degree)):
            raise TablesError(path, "kernel_params", f"poly degree must be a positive integer, found {degree:g}")
        with naming_file(path):
            return cls(
                source_names=tuple(t.channels["source"]), target_names=tuple(t.channels["target"]),
                source_features=a["source_features"], train_inputs=a["train_inputs"],
                dual_coef=a["dual_coef"], kernel_col_mean=a["kernel_col_mean"],
                kernel_grand_mean=float(a["kernel_grand_mean"][0]), target_mean=a["target_mean"],
                kernel=kernels[code], gamma=gamma, coef0=coef0, degree=int(degree), units=t.units,
                metadata=t.metadata,
            )

    # -- per frame ---------------------------------------------------------
    def predict_features(self, x: np.ndarray) -> np.ndarray:
        """Target weights (n_target,) float32 from source feature displacements x (n_features,)."""
        x = np.asarray(x, np.float32)
        return self._predict(self.train_inputs @ x, float(x @ x))

    def predict_weights(self, source_weights: np.ndarray) -> np.ndarray:
        """Target weights (n_target,) float32 from source-character weights (n_source,)."""
        w = np.asarray(source_weights, np.float32)
        return self._predict(self._train_by_source @ w, float(w @ self._source_gram @ w))

    def _predict(self, k: np.ndarray, x_sq: float) -> np.ndarray:
        """Eq. 10 from the inner products k_i = X_i·x (modified in place) and ‖x‖²."""
        if self._code == 1:  # rbf: exp(−γ (‖x‖² + ‖X_i‖² − 2 X_i·x))
            k *= -2.0
            k += self._train_sq
            k += x_sq
            np.maximum(k, 0.0, out=k)
            k *= -self.gamma
            np.exp(k, out=k)
        elif self._code == 2:  # poly: (γ X_i·x + coef0)^degree
            k *= self.gamma
            k += self.coef0
            k **= self.degree
        y = k @ self.dual_coef  # Ouzounis eq. 10, one kernel row
        y -= k.mean() * self._coef_sum  # Ouzounis eq. 8, centring of the test row
        y += self._offset
        return y

    def _folded(self, channels: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(X F M, Mᵀ FᵀF M, G) for a channel tuple, M its :class:`ChannelMap` matrix; cached.

        G (n_target, n_channels) is the whole of eq. 10 for the linear kernel, which is linear in
        the weights: ŷ = Bᵀ A v − s (1ᵀ A v)/n + c with A = X F M, so ŷ = G v + c (None otherwise).
        """
        folded = self._maps.get(channels)
        if folded is None:
            M = self.source_map(channels).matrix.astype(np.float64)
            A = self._train_by_source.astype(np.float64) @ M
            G = None
            if self._code == 0:
                B = self.dual_coef.astype(np.float64)
                G = (B.T @ A - np.outer(self._coef_sum.astype(np.float64), A.mean(axis=0))).astype(np.float32)
            folded = self._maps[channels] = (
                A.astype(np.float32), (M.T @ self._source_gram.astype(np.float64) @ M).astype(np.float32), G,
            )
        return folded

    def source_map(self, channels: tuple[str, ...]) -> ChannelMap:
        """The map from a frame's channel names onto the source character's shapes."""
        return ChannelMap.build(channels, self.source_names)

    def apply(self, frame: Frame) -> np.ndarray | None:
        """Target weights (n_target,) float32 for a frame with weights; None for a frame without.

        Channels are matched to the source shapes by name (NaN, a missing
        weight, counts as 0), with the channel map folded into the kernel's
        input product once per distinct channel tuple.
        """
        if frame.weights is None:
            return None
        by_channel, gram, linear = self._folded(frame.channels)
        v = frame.weights
        if np.isnan(v).any():
            v = np.where(np.isnan(v), np.float32(0.0), v)
        if linear is not None:  # linear kernel: eq. 10 folded into one (n_target, n_channels) product
            y = linear @ v
            y += self._offset
            return y
        return self._predict(by_channel @ v, float(v @ gram @ v))
