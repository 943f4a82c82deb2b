"""Expression parameters of Yano & Harada (2009), eq. 6: control displacements fitted by least squares.

For each existing expression (a blendshape with vertex displacements D_s)
the control-point displacements U_s that best reproduce it through the basis
solve min ||B U_s - D_s||² (eq. 6), here with one QR factorisation of the
basis shared by every shape.

Symbols → code names:

    B (basis matrix, n × n_c)          basis (dense or sparse), the compact basis at runtime
    D_s (displacements of shape s)     deltas[s], (n, 3)
    U_s (expression parameters)        params_[s], (n_c, 3)

Errors are measured on the vertices a shape moves by more than 1 % of its
largest displacement, within ``evaluate`` (default: every vertex): RMS and
worst vertex error in units, and the RMS relative to the shape's largest
displacement.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.linalg import qr, solve_triangular

from facepuppet.runtime.elastic.model import ElasticModel, no_muscles
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.basis import DEFAULT_FIXED_RATIO, DEFAULT_K, ElasticBasis, fixed_region
from facepuppet.offline.elastic.control_points import ControlPoints
from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.elastic.muscles import default_muscles, muscle_sections
from facepuppet.offline.elastic.rigid_parts import rigid_labels

MOVED_FRACTION = 0.01


class ExpressionFit:
    """Least-squares (QR) expression parameters for every shape of a character (eq. 6).

    Attributes (after fit)
    ----------------------
    params_ : ndarray of shape (n_shapes, n_c, 3), float32, units
    rms_ : ndarray of shape (n_shapes,), float64, units (NaN where the shape moves nothing evaluated)
    worst_ : ndarray of shape (n_shapes,), float64, units, largest vertex error
    relative_ : ndarray of shape (n_shapes,), float64, rms_ / largest displacement
    """

    def fit(self, basis: np.ndarray | sp.spmatrix, deltas: np.ndarray,
            evaluate: np.ndarray | None = None) -> ExpressionFit:
        """Fit eq. 6.

        Parameters
        ----------
        basis : ndarray or sparse matrix of shape (n, n_c), float
        deltas : ndarray of shape (n_shapes, n, 3), float, units
        evaluate : ndarray of shape (n,), bool, or None; vertices the errors are measured on
        """
        b = basis.toarray() if sp.issparse(basis) else np.asarray(basis, np.float64)
        d = np.asarray(deltas, np.float64)
        if d.ndim != 3 or d.shape[1:] != (b.shape[0], 3):
            raise ValueError(f"deltas: expected shape (n_shapes, {b.shape[0]}, 3), got {d.shape}")
        q, r = qr(b, mode="economic")
        rank_floor = np.abs(np.diag(r)).max() * 1e-10
        if (np.abs(np.diag(r)) <= rank_floor).any():
            raise InputFileError("basis: rank deficient (two control points with identical basis functions?)")
        s_count, n, _ = d.shape
        rhs = d.transpose(1, 0, 2).reshape(n, s_count * 3)
        u = solve_triangular(r, q.T @ rhs)  # Yano & Harada eq. 6: R U = Qᵀ D
        self.params_ = u.reshape(-1, s_count, 3).transpose(1, 0, 2).astype(np.float32)
        self.basis_ = b
        self.rms_, self.worst_, self.relative_ = reconstruction_errors(b, self.params_, d, evaluate)
        return self

    def reconstruct(self, s: int) -> np.ndarray:
        """Vertex displacements of shape ``s`` from its parameters, (n, 3) float64."""
        return self.basis_ @ self.params_[s].astype(np.float64)  # Yano & Harada eq. 5


def reconstruction_errors(basis: np.ndarray | sp.spmatrix, params: np.ndarray, deltas: np.ndarray,
                          evaluate: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per shape (rms, worst, relative) errors of B U_s against D_s; see the module docstring."""
    b = basis.toarray() if sp.issparse(basis) else np.asarray(basis, np.float64)
    d = np.asarray(deltas, np.float64)
    mask = np.ones(d.shape[1], bool) if evaluate is None else np.asarray(evaluate, bool)
    rms, worst, rel = (np.full(len(d), np.nan) for _ in range(3))
    for s in range(len(d)):
        length = np.linalg.norm(d[s], axis=1)
        largest = length.max()
        moved = mask & (length > MOVED_FRACTION * largest)
        if not moved.any():
            continue
        err = np.linalg.norm(b[moved] @ params[s].astype(np.float64) - d[s][moved], axis=1)
        rms[s] = np.sqrt(np.mean(err**2))
        worst[s] = err.max()
        rel[s] = rms[s] / largest
    return rms, worst, rel


def storage_bytes(n_vertices: int, n_shapes: int, n_controls: int, k: int) -> dict:
    """Bytes of the compact elastic tables versus dense float32 position deltas (the ratio of §7).

    Compact: per vertex k uint16 indices, k float32 weights and k float32
    3-vectors (normal gradients) and one int32 rigid-part label; per shape
    n_c × 3 float32 parameters.
    """
    compact = n_vertices * (k * (2 + 4 + 12) + 4) + n_shapes * n_controls * 3 * 4
    dense = n_shapes * n_vertices * 3 * 4
    return {"compact_bytes": compact, "dense_bytes": dense, "ratio": dense / compact}


def target_fixed_mask(vertices: np.ndarray, points: ControlPoints, fixed_ratio: float) -> np.ndarray:
    """The §4 fixed region of a mesh from its ``nose_tip`` and ``forehead`` control points, (n,) bool."""
    v = np.asarray(vertices, np.float64)
    return fixed_region(v, v[points.vertex("nose_tip")], v[points.vertex("forehead")], fixed_ratio)


def build_model(vertices: np.ndarray, triangles: np.ndarray, points: ControlPoints, params: np.ndarray,
                shape_names: Sequence[str], *, k: int = DEFAULT_K, fixed_ratio: float = DEFAULT_FIXED_RATIO,
                units: str = "cm", with_muscles: bool = True, basis: ElasticBasis | None = None,
                metrics: dict | None = None, deltas: np.ndarray | None = None) -> tuple[ElasticModel, ElasticBasis]:
    """An ElasticModel from a mesh, its control points and expression parameters (n_shapes, n_c, 3).

    Handle-free pieces below the mouth (lower teeth, tongue) become the rigid
    jaw part (:mod:`.rigid_parts`), chosen from ``deltas`` (n_shapes, n, 3)
    when given, else by the inner-lip midline. Returns (model, basis);
    ``basis`` may be passed in when already fitted.
    """
    v = np.asarray(vertices, np.float64)
    if basis is None:
        basis = ElasticBasis(k=k).fit(v, triangles, points.vertices, target_fixed_mask(v, points, fixed_ratio),
                                      points.names)
    positions = v[points.vertices]
    muscles = default_muscles(positions, points) if with_muscles else []
    labels, anchors = rigid_labels(v, points, basis.detached_mask_, params, deltas,
                                   pieces=components(len(v), triangles)[1])
    arrays = {
        "basis_indices": basis.compact_indices_,
        "basis_weights": basis.compact_weights_,
        "basis_gradients": basis.compact_gradients_,
        "control_vertices": points.vertices.astype(np.int64),
        "control_positions": positions.astype(np.float32),
        "params": np.asarray(params, np.float32).reshape(len(shape_names), len(points.names), 3),
        **(muscle_sections(muscles, positions) if muscles else no_muscles(len(points.names))),
        "rigid_labels": labels,
        "rigid_anchors": anchors,
    }
    model = ElasticModel(
        arrays=arrays, shape_names=tuple(shape_names), control_names=tuple(points.names),
        muscle_names=tuple(m.name for m in muscles), units=units,
        metadata={"settings": {"k": int(basis.k), "fixed_ratio": float(fixed_ratio)}, "metrics": dict(metrics or {})},
    )
    return model, basis


def fit_character(character: Character, points: ControlPoints, *, k: int = DEFAULT_K,
                  fixed_ratio: float = DEFAULT_FIXED_RATIO,
                  with_muscles: bool = True) -> tuple[ElasticModel, ElasticBasis, dict]:
    """Basis, eq. 6 parameters and error report for every shape of ``character``.

    Errors are measured on the components that carry control points (the
    skin); components held fixed (eyes, teeth) are reported apart.

    Returns (model, basis, report) with report a JSON-ready dict.
    """
    v = character.vertices.astype(np.float64)
    basis = ElasticBasis(k=k).fit(v, character.triangles, points.vertices,
                                  target_fixed_mask(v, points, fixed_ratio), points.names)
    deltas = character.dense_deltas().astype(np.float64)
    skin = ~basis.detached_mask_
    compact = ExpressionFit().fit(basis.compact_matrix(), deltas, skin)  # Yano & Harada eq. 6
    full = ExpressionFit().fit(basis.weights_, deltas, skin)
    rel, rel_full = compact.relative_, full.relative_
    ok = np.isfinite(rel)
    store = storage_bytes(character.n_vertices, character.n_shapes, len(points.names), k)
    report = {
        "n_vertices": character.n_vertices, "n_controls": len(points.names), "k": k, "fixed_ratio": fixed_ratio,
        "fixed_vertices": int(basis.fixed_mask_.sum()), "detached_vertices": int(basis.detached_mask_.sum()),
        "basis_seconds": basis.solve_seconds_,
        "shapes": {
            name: {"rms_cm": float(compact.rms_[s]), "worst_cm": float(compact.worst_[s]),
                   "relative": float(rel[s]), "relative_full_basis": float(rel_full[s])}
            for s, name in enumerate(character.shape_names) if ok[s]
        },
        "skipped_shapes": [n for s, n in enumerate(character.shape_names) if not ok[s]],
        "median_relative": float(np.median(rel[ok])), "worst_relative": float(np.max(rel[ok])),
        "median_rms_cm": float(np.median(compact.rms_[ok])), "worst_cm": float(np.max(compact.worst_[ok])),
        "median_relative_full_basis": float(np.median(rel_full[ok])),
        "truncation_added_median": float(np.median(rel[ok] - rel_full[ok])),
        "truncation_added_worst": float(np.max(rel[ok] - rel_full[ok])),
        **store,
    }
    model, _ = build_model(v, character.triangles, points, compact.params_, character.shape_names, k=k,
                           fixed_ratio=fixed_ratio, units=character.units, with_muscles=with_muscles,
                           basis=basis, metrics={k_: report[k_] for k_ in report if k_ != "shapes"}, deltas=deltas)
    report.update(rigid_report(model, character, deltas))
    model.metadata["metrics"].update({k_: report[k_] for k_ in ("rigid_vertices", "rigid_jaw_open_cm")})
    return model, basis, report


def rigid_report(model: ElasticModel, character: Character, deltas: np.ndarray) -> dict:
    """Rigid-part size and, where the character has ``jawOpen``, the RMS error (cm) of the rigid
    vertices there: with the rigid jaw and as if held fixed."""
    on = model.arrays["rigid_labels"] >= 0
    out = {"rigid_vertices": int(on.sum()), "rigid_jaw_open_cm": None, "rigid_jaw_open_fixed_cm": None}
    if on.any() and "jawOpen" in character.shape_names:
        s = character.shape_names.index("jawOpen")
        rest = character.vertices
        pos, _ = model.deform(model.arrays["params"][s], rest, np.tile([0, 0, 1.0], (len(rest), 1)))
        err = np.linalg.norm(pos[on] - rest[on] - deltas[s][on], axis=1)
        out["rigid_jaw_open_cm"] = float(np.sqrt(np.mean(err**2)))
        out["rigid_jaw_open_fixed_cm"] = float(np.sqrt(np.mean((deltas[s][on] ** 2).sum(1))))
    return out
