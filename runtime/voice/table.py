"""The ``voice`` table: a learned map from causal log-mel features to ARKit mouth channels, evaluated per hop.

``fit-voice`` (offline) writes it; the run-time voice stage reads it with NumPy alone. It holds the
features it was fitted on (:class:`~facepuppet.runtime.voice.features.FeatureSpec`, so run time computes
the same numbers), their standardisation, and one of four models, the one that won the fit's
cross-validation:

=====  ==========  ==================================================================================
code   model       evaluation of a standardised feature vector z (n_features,)
=====  ==========  ==================================================================================
0      level       ``y = z W + ȳ`` with W zero but for the level row: the voice level alone (baseline)
1      ridge       ``y = z W + ȳ``
2      kpls        Ouzounis et al. eq. 10 with an RBF kernel: ``k_i = exp(-γ ‖z - X_i‖²)``,
                   ``y = (k - mean(k)) B - k̄ B + k̿ ΣB + ȳ`` (the centring of eq. 8 folded into constants)
3      blend       ``y = z W + ȳ + Σ_t tree_t(z)``: ridge and boosted trees, each weight already halved
                   (:mod:`facepuppet.runtime.voice.trees`; ȳ holds both models' constants)
=====  ==========  ==================================================================================

Outputs are clamped to [0, 1], and a level under ``gate_db`` fades them to 0 over ``GATE_SPAN_DB``: silence
is a closed mouth whatever the model makes of the noise floor. The level and ``gate_db`` are in the features'
dB: dBFS, or relative to the speaker's running level where the features are (``feature_level_ref``).

Symbols and names: W ``coef``; ȳ ``output_mean``; X ``train_inputs``; B ``dual_coef``; k̄
``kernel_col_mean``; k̿ ``kernel_grand_mean``; γ ``model_params[1]``; the trees ``tree_feature``,
``tree_threshold``, ``tree_value``.
"""

from __future__ import annotations

import math
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
from facepuppet.runtime.voice.features import FeatureSpec
from facepuppet.runtime.voice.trees import MAX_TREES, TreeEvaluator, depth_of

if TYPE_CHECKING:
    from pathlib import Path

MODELS = ("level", "ridge", "kpls", "blend")
GATE_SPAN_DB = 6.0  # the gate opens fully this far above gate_db
MAX_TRAIN = 4096  # kernel rows evaluated per hop at most: bounds a hostile table's cost per block

VOICE_SCHEMA = register_schema(
    TableSchema(
        kind="voice",
        sections={
            "feature_spec": Section("float64", (8,), "sample_rate, window_s, hop_s, n_mels, fmin, fmax, n_taps, step"),
            "feature_level_ref": Section("float64", (1,), "level_ref_s: the features are dB relative to a running "
                                                          "level of this time constant (absent: dBFS)", optional=True),
            "feature_mean": Section("float32", ("n_features",), "feature means (standardisation)"),
            "feature_scale": Section("float32", ("n_features",), "feature standard deviations"),
            "model_params": Section("float64", (4,), "model code (0 level, 1 ridge, 2 kpls, 3 blend), gamma, "
                                                     "lookahead_s, gate_db"),
            "output_mean": Section("float32", ("n_outputs",), "mean of the training outputs"),
            "coef": Section("float32", ("n_features", "n_outputs"), "linear weights W (level, ridge, blend)",
                            optional=True),
            "train_inputs": Section("float32", ("n_train", "n_features"), "kpls: standardised training inputs X",
                                    optional=True),
            "dual_coef": Section("float32", ("n_train", "n_outputs"), "kpls: dual coefficients B, eq. 10",
                                 optional=True),
            "kernel_col_mean": Section("float32", ("n_train",), "kpls: column means of the Gram matrix",
                                       optional=True),
            "kernel_grand_mean": Section("float32", (1,), "kpls: grand mean of the Gram matrix", optional=True),
            "tree_feature": Section("int32", ("n_trees", "n_internal"), "blend: feature of each tree node (heap order)",
                                    optional=True),
            "tree_threshold": Section("float64", ("n_trees", "n_internal"), "blend: threshold of each tree node",
                                      optional=True),
            "tree_value": Section("float32", ("n_trees", "n_leaves"), "blend: leaf values", optional=True),
        },
        channels=("outputs",),
        channel_dims={"outputs": "n_outputs"},
        version=2,  # 2: the blend model (code 3) and its tree sections
    )
)

_KPLS = ("train_inputs", "dual_coef", "kernel_col_mean", "kernel_grand_mean")
_TREES = ("tree_feature", "tree_threshold", "tree_value")


def spec_from_array(a: np.ndarray, path: str | os.PathLike | None = None,
                    level_ref: np.ndarray | None = None) -> FeatureSpec:
    """The FeatureSpec of a ``feature_spec`` section and the optional ``feature_level_ref`` (TablesError naming
    the field when they are not one)."""
    rate, window, hop, n_mels, fmin, fmax, n_taps, step = (float(v) for v in a)
    ref = float(level_ref[0]) if level_ref is not None else 0.0
    if not (math.isfinite(ref) and (ref == 0 or 0.1 <= ref <= 600)):
        raise TablesError(path, "feature_level_ref", f"expected 0 or 0.1..600 s, found {ref!r}")
    ints = (n_mels, n_taps, step)
    if not all(math.isfinite(v) and v == int(v) for v in ints):
        raise TablesError(path, "feature_spec", f"n_mels, n_taps and step must be integers, found {ints}")
    try:
        return FeatureSpec(rate, window, hop, int(n_mels), fmin, fmax, int(n_taps), int(step), ref)
    except ValueError as exc:
        raise TablesError(path, "feature_spec", str(exc)) from None


def spec_to_array(spec: FeatureSpec) -> np.ndarray:
    return np.array([spec.sample_rate, spec.window_s, spec.hop_s, spec.n_mels, spec.fmin, spec.fmax,
                     spec.n_taps, spec.step], np.float64)


@dataclass(frozen=True, eq=False)
class VoiceTable:
    """A fitted voice table, validated when built.

    Attributes
    ----------
    outputs : tuple of n_outputs str, ARKit channel names
    spec : FeatureSpec
    model : str, one of MODELS
    feature_mean, feature_scale : ndarray of shape (n_features,), float32
    output_mean : ndarray of shape (n_outputs,), float32
    coef : ndarray of shape (n_features, n_outputs), float32, or None (kpls)
    tree_feature, tree_threshold : ndarray of shape (n_trees, n_internal), int32 / float64, and tree_value
        (n_trees, n_leaves) float32: blend only (:mod:`facepuppet.runtime.voice.trees`)
    train_inputs : ndarray of shape (n_train, n_features), float32, or None; dual_coef (n_train, n_outputs),
        kernel_col_mean (n_train,), kernel_grand_mean float: kpls only
    gamma : float, the RBF width (kpls)
    lookahead_s : float, seconds of sound after a mouth frame the features saw (0: causal)
    gate_db : float, dBFS, the level under which the mouth closes
    metadata : dict, settings / metrics / input hash of the manifest
    """

    outputs: tuple[str, ...]
    spec: FeatureSpec
    model: str
    feature_mean: np.ndarray
    feature_scale: np.ndarray
    output_mean: np.ndarray
    coef: np.ndarray | None = None
    train_inputs: np.ndarray | None = None
    dual_coef: np.ndarray | None = None
    kernel_col_mean: np.ndarray | None = None
    kernel_grand_mean: float = 0.0
    tree_feature: np.ndarray | None = None
    tree_threshold: np.ndarray | None = None
    tree_value: np.ndarray | None = None
    gamma: float = 1.0
    lookahead_s: float = 0.0
    gate_db: float = -55.0
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.model not in MODELS:
            raise TablesError(None, "model_params", f"model must be one of {MODELS}, got {self.model!r}")
        set_(self, "outputs", tuple(self.outputs))
        arrays = self._arrays()
        for name, arr in coerce(VOICE_SCHEMA, arrays).items():
            if hasattr(self, name) and name not in ("kernel_grand_mean",):
                set_(self, name, arr)
        arrays = self._arrays()
        validate(VOICE_SCHEMA, arrays, {"outputs": list(self.outputs)})
        n_features = len(self.feature_mean)
        if n_features != self.spec.n_features:
            raise TablesError(None, "feature_mean", f"expected {self.spec.n_features} features (n_taps x n_mels + 1) "
                                                    f"for feature_spec, found {n_features}")
        if self.model == "kpls":
            missing = [s for s in _KPLS if arrays.get(s) is None]
            if missing:
                raise TablesError(None, missing[0], "the kpls model needs this section")
            if len(self.train_inputs) > MAX_TRAIN:
                raise TablesError(None, "train_inputs", f"at most {MAX_TRAIN} rows, found {len(self.train_inputs)}")
            if not (math.isfinite(self.gamma) and self.gamma > 0):
                raise TablesError(None, "model_params", f"gamma must be a positive number, found {self.gamma!r}")
        elif self.coef is None:
            raise TablesError(None, "coef", f"the {self.model} model needs this section")
        if self.model == "blend":
            self._check_trees(arrays, n_features)
        if not (np.all(self.feature_scale > 0)):
            raise TablesError(None, "feature_scale", "every scale must be positive")
        for name, v in (("lookahead_s", self.lookahead_s), ("gate_db", self.gate_db)):
            if not math.isfinite(v) or (name == "lookahead_s" and not 0 <= v <= 1.0):
                raise TablesError(None, "model_params", f"{name} out of range: {v!r}")
        set_(self, "_inv_scale", (1.0 / self.feature_scale.astype(np.float64)).astype(np.float32))
        if self.model == "kpls":
            B = self.dual_coef.astype(np.float64)
            s = B.sum(axis=0)
            c = -self.kernel_col_mean.astype(np.float64) @ B + self.kernel_grand_mean * s + self.output_mean
            set_(self, "_coef_sum", s.astype(np.float32))
            set_(self, "_offset", c.astype(np.float32))
            set_(self, "_train_sq", (self.train_inputs.astype(np.float64) ** 2).sum(1).astype(np.float32))

    def _check_trees(self, arrays: dict, n_features: int) -> None:
        missing = [s for s in _TREES if arrays.get(s) is None]
        if missing:
            raise TablesError(None, missing[0], "the blend model needs this section")
        n_trees, n_internal = self.tree_feature.shape
        if depth_of(n_internal, self.tree_value.shape[1]) is None:
            raise TablesError(None, "tree_value", f"{n_internal} nodes and {self.tree_value.shape[1]} leaves per tree "
                                                  "are not complete trees of depth 1..6")
        if not 0 < n_trees <= MAX_TREES or n_trees % len(self.outputs):
            raise TablesError(None, "tree_feature", f"expected a multiple of {len(self.outputs)} trees (one run per "
                                                    f"output), at most {MAX_TREES}, found {n_trees}")
        if self.tree_feature.min() < 0 or self.tree_feature.max() >= n_features:
            raise TablesError(None, "tree_feature", f"feature indices must lie in 0..{n_features - 1}")

    # -- tables ------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        a = {
            "feature_spec": spec_to_array(self.spec),
            "feature_level_ref": np.array([self.spec.level_ref_s]) if self.spec.level_ref_s > 0 else None,
            "feature_mean": self.feature_mean, "feature_scale": self.feature_scale,
            "model_params": np.array([MODELS.index(self.model), self.gamma, self.lookahead_s, self.gate_db],
                                     np.float64),
            "output_mean": self.output_mean,
        }
        if self.coef is not None:
            a["coef"] = self.coef
        if self.model == "kpls":
            a.update(train_inputs=self.train_inputs, dual_coef=self.dual_coef, kernel_col_mean=self.kernel_col_mean,
                     kernel_grand_mean=np.array([self.kernel_grand_mean], np.float32))
        if self.model == "blend":
            a.update(tree_feature=self.tree_feature, tree_threshold=self.tree_threshold, tree_value=self.tree_value)
        return {k: v for k, v in a.items() if v is not None}

    def save(self, path: str | os.PathLike) -> Path:
        """Write a ``voice`` tables file; returns its path."""
        settings = dict(self.metadata.get("settings", {}))
        settings.update(model=self.model, lookahead_ms=round(self.lookahead_s * 1000.0, 3))
        return save_tables(path, "voice", self._arrays(), channels={"outputs": list(self.outputs)},
                           settings=settings, metadata=self.metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> VoiceTable:
        """Load and validate a ``voice`` tables file (TablesError naming the file and the field)."""
        t = load_tables(path, kind="voice")
        a = t.arrays
        spec = spec_from_array(a["feature_spec"], path, a.get("feature_level_ref"))
        code, gamma, lookahead, gate = (float(v) for v in a["model_params"])
        if code not in (0.0, 1.0, 2.0, 3.0):
            raise TablesError(path, "model_params", f"model code must be 0, 1, 2 or 3, found {code:g}")
        kgm = a.get("kernel_grand_mean")
        with naming_file(path):
            return cls(outputs=tuple(t.channels["outputs"]), spec=spec, model=MODELS[int(code)],
                       feature_mean=a["feature_mean"], feature_scale=a["feature_scale"],
                       output_mean=a["output_mean"], coef=a.get("coef"), train_inputs=a.get("train_inputs"),
                       dual_coef=a.get("dual_coef"), kernel_col_mean=a.get("kernel_col_mean"),
                       kernel_grand_mean=float(kgm[0]) if kgm is not None else 0.0,
                       tree_feature=a.get("tree_feature"), tree_threshold=a.get("tree_threshold"),
                       tree_value=a.get("tree_value"), gamma=gamma,
                       lookahead_s=lookahead, gate_db=gate, metadata=t.metadata)

    # -- evaluation --------------------------------------------------------
    def evaluator(self) -> VoiceEvaluator:
        """A per-hop evaluator with its own buffers (one per thread that predicts)."""
        return VoiceEvaluator(self)

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Outputs (k, n_outputs) float64 for feature rows X (k, n_features): the evaluator row by row."""
        ev = self.evaluator()
        return np.array([ev(np.asarray(x, np.float64)).astype(np.float64) for x in X]).reshape(
            len(X), len(self.outputs))


class VoiceEvaluator:
    """One table's evaluation into buffers made once: ``ev(x)`` returns a view it overwrites next call."""

    def __init__(self, table: VoiceTable) -> None:
        self.table = table
        n_f, n_o = len(table.feature_mean), len(table.outputs)
        self._z = np.zeros(n_f, np.float32)
        self._y = np.zeros(n_o, np.float32)
        self._centre = np.zeros(n_o, np.float32)
        self._k = np.zeros(len(table.train_inputs), np.float32) if table.model == "kpls" else None
        n_train = len(table.train_inputs) if table.model == "kpls" else 1
        self._mean_row = np.full(n_train, 1.0 / n_train, np.float32)  # mean(k) as a dot product
        self._one, self._zero = np.float32(1.0), np.float32(0.0)
        self._minus_two, self._minus_gamma = np.float32(-2.0), np.float32(-table.gamma)
        self._trees = TreeEvaluator(table.tree_feature, table.tree_threshold, table.tree_value,
                                    n_o, n_f) if table.model == "blend" else None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        t, z, y = self.table, self._z, self._y
        np.copyto(z, x, casting="unsafe")
        np.subtract(z, t.feature_mean, out=z)
        np.multiply(z, t._inv_scale, out=z)
        if t.model == "kpls":
            k = self._k
            np.dot(t.train_inputs, z, out=k)
            # rbf: exp(-γ (‖z‖² + ‖X_i‖² − 2 X_i·z))
            np.multiply(k, self._minus_two, out=k)
            np.add(k, t._train_sq, out=k)
            np.add(k, np.float32(np.dot(z, z)), out=k)
            np.maximum(k, self._zero, out=k)
            np.multiply(k, self._minus_gamma, out=k)
            np.exp(k, out=k)
            np.dot(k, t.dual_coef, out=y)  # Ouzounis eq. 10, one kernel row
            np.multiply(t._coef_sum, np.float32(np.dot(k, self._mean_row)), out=self._centre)
            np.subtract(y, self._centre, out=y)  # Ouzounis eq. 8, centring of the test row
            np.add(y, t._offset, out=y)
        else:
            np.dot(z, t.coef, out=y)
            np.add(y, t.output_mean, out=y)
            if self._trees is not None:
                self._trees(z, y)
        np.minimum(y, self._one, out=y)
        np.maximum(y, self._zero, out=y)
        level = float(x[-1])
        if level < t.gate_db + GATE_SPAN_DB:
            np.multiply(y, np.float32(max(0.0, (level - t.gate_db) / GATE_SPAN_DB)), out=y)
        return y
